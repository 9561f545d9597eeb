"""The failure sequence of a run of a bonded building: its members (``wall xmin s0`` = the
ground-floor wall on the x-min side, ``column s1``, ``slab s0``, ``foundation``) in the order of
their first broken bond in the run's ``bond_breaks.csv``::

    python -m fcm_fsi failure-sequence OUTPUT_DIR      # reads case.resolved.yaml and bond_breaks.csv

A bond joining two members counts for both. The naming is in fcm_fsi/dem/failure_sequence.py.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..config import ConfigError, load_case
from ..dem.failure_sequence import MemberFailure, sequence_of_case
from ..io.csv import read_series


def read_breaks(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, block_a, block_b) of a ``bond_breaks.csv`` (empty arrays when no bond broke)."""
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"{path}: not found (a run with bonded blocks writes it)")
    if len(path.read_text().splitlines()) < 2:      # the header only: read_series needs a row
        return np.zeros(0), np.zeros(0, int), np.zeros(0, int)
    col = read_series(path)
    try:
        return col["t"], col["block_a"].astype(int), col["block_b"].astype(int)
    except KeyError as err:
        raise ConfigError(f"{path}: no column {err} (expected t, bond, block_a, block_b)") from None


def sequence_of_run(out_dir: Path) -> list[MemberFailure]:
    """The failure sequence of the run in ``out_dir`` (its case.resolved.yaml and bond_breaks.csv)."""
    out_dir = Path(out_dir)
    return sequence_of_case(load_case(out_dir / "case.resolved.yaml"), *read_breaks(out_dir / "bond_breaks.csv"))


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("output", type=Path, help="a run's output folder")


def run(args: argparse.Namespace) -> int:
    try:
        seq = sequence_of_run(args.output)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if not seq:
        print("no bond broke")
        return 0
    print("member            first break [s]  last break [s]  bonds broken")
    for f in seq:
        print(f"{f.member:18s} {f.first_break:14.4f} {f.last_break:15.4f} {f.bonds:13d}")
    return 0
