"""Figures of the verification cases: drawn and saved by rank 0 only, with the Agg backend."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path


def save_figure(out_dir: Path, name: str, comm, draw: Callable, figsize: tuple[float, float] = (6.4, 4.4)) -> None:
    """``draw(fig)`` on a new figure of ``figsize`` [in], saved as ``out_dir/name`` (110 dpi) by
    rank 0 of ``comm`` (any rank when ``comm`` is None)."""
    if comm is not None and comm.rank != 0:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=figsize)
    draw(fig)
    fig.tight_layout()
    fig.savefig(Path(out_dir) / name, dpi=110)
    plt.close(fig)
