"""Scalar time series as CSV with units in the header, flushed at every row (rank 0 only)."""
from __future__ import annotations

from pathlib import Path


class TimeSeriesCSV:
    """``columns`` maps column name → unit; header is ``name [unit]``.

    Opened in append mode on restart so that the series continues; every row is flushed
    so a run killed mid-way leaves a readable file.
    """

    def __init__(self, path: Path, columns: dict[str, str], rank: int = 0, append: bool = False):
        self.columns = list(columns)
        self._fh = None
        if rank != 0:
            return
        path = Path(path)
        exists = append and path.exists()
        self._fh = open(path, "a" if exists else "w", buffering=1)
        if not exists:
            self._fh.write(",".join(f"{c} [{u}]" for c, u in columns.items()) + "\n")
            self._fh.flush()

    def write(self, **values: float) -> None:
        if self._fh is None:
            return
        self._fh.write(",".join(repr(float(values[c])) for c in self.columns) + "\n")
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
