"""Scalar time series as CSV with units in the header, flushed at every row (rank 0 only)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


class TimeSeriesCSV:
    """``columns`` maps column name → unit; header is ``name [unit]``.

    Opened in append mode on restart so that the series continues (``append``; with
    ``resume_at`` = the checkpoint time, rows after it — written after the checkpoint, before
    the earlier run stopped — are dropped first); every row is flushed so a run killed
    mid-way leaves a readable file. ``lazy`` opens the file at the first row (or at
    :meth:`close`), so that an owner built before it knows of a restart can still call
    :meth:`resume`.
    """

    def __init__(self, path: Path, columns: dict[str, str], rank: int = 0, append: bool = False,
                 resume_at: float | None = None, lazy: bool = False):
        self.columns = list(columns)
        self._units = dict(columns)
        self._path, self._append, self._resume_at = Path(path), append, resume_at
        self._fh, self._active = None, rank == 0
        if self._active and not lazy:
            self._open()

    def resume(self, t: float) -> None:
        """Continue the file of an earlier run from a restart at time ``t`` [s] (before the
        first row of a ``lazy`` series)."""
        if self._fh is not None:
            raise RuntimeError(f"{self._path}: resume() after the file was opened")
        self._append, self._resume_at = True, float(t)

    def _open(self) -> None:
        path = self._path
        exists = self._append and path.exists()
        if exists and self._resume_at is not None:
            drop_rows_after(path, self._resume_at)
        self._fh = open(path, "a" if exists else "w", buffering=1)
        if not exists:
            self._fh.write(",".join(f"{c} [{u}]" for c, u in self._units.items()) + "\n")
            self._fh.flush()

    def write(self, **values: float) -> None:
        if not self._active:
            return
        if self._fh is None:
            self._open()
        self._fh.write(",".join(repr(float(values[c])) for c in self.columns) + "\n")
        self._fh.flush()

    def close(self) -> None:
        if self._active and self._fh is None:
            self._open()                      # a lazy series without rows still gets its header
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        self._active = False


def drop_rows_after(path: Path, t: float) -> int:
    """Remove the rows of a series CSV whose ``t [s]`` column exceeds ``t`` (with a relative
    tolerance of 1e-12 for times summed from steps); returns how many were removed."""
    lines = Path(path).read_text().splitlines(keepends=True)
    if not lines:
        return 0
    names = [h.split(" [")[0] for h in lines[0].rstrip("\n").split(",")]
    if "t" not in names:
        return 0
    col, limit = names.index("t"), t + 1e-12 * max(abs(t), 1.0)
    keep = [ln for ln in lines[1:] if ln.strip() and float(ln.split(",")[col]) <= limit]
    Path(path).write_text(lines[0] + "".join(keep))
    return len(lines) - 1 - len(keep)



def read_series(path: Path) -> dict[str, np.ndarray]:
    """Columns of a CSV written by :class:`TimeSeriesCSV` (series.csv, bodies.csv, ...) by
    name, the units stripped from the header."""
    path = Path(path)
    names = [h.split(" [")[0] for h in path.read_text().splitlines()[0].split(",")]
    data = np.atleast_2d(np.loadtxt(path, delimiter=",", skiprows=1))
    return {n: data[:, i] for i, n in enumerate(names)}
