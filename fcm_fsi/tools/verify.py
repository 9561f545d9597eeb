"""Verification cases against references.

    python -m fcm_fsi verify NAME --level quick|full [--np N] [--out DIR]
    python -m fcm_fsi verify --list
    python -m fcm_fsi verify all --level full --report docs/verification
    python -m fcm_fsi verify --out verification --report docs/verification   (report only)
    python -m fcm_fsi verify NAME --level full --out DIR --resume   (continue from DIR's checkpoints)

Writes DIR/NAME/metrics.json and PNG plots, prints a table, exits 1 when a metric fails.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..io.logging import setup_logging
from ..verify.registry import load_all
from ..verify.runner import run_one, write_report


def positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("name", nargs="?", help="case name, or 'all'")
    ap.add_argument("--level", choices=["quick", "full"], default="quick")
    ap.add_argument("--np", type=int, default=None, help="MPI ranks (default: the case's own)")
    ap.add_argument("--out", type=Path, default=Path("verification"))
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--report", type=Path, default=None, help="with 'all': write a markdown report here")
    ap.add_argument("--log-level", choices=["DEBUG", "INFO", "WARNING"], default="WARNING",
                    help="progress messages of the cases (INFO: e.g. per-cycle progress of long runs)")
    ap.add_argument("--resume", action="store_true",
                    help="runs with a checkpoint.h5 of their own case under --out continue from it")
    ap.add_argument("--ranks-per-run", type=positive_int, default=1,
                    help="cases made of several independent runs (block_overturn): ranks per run; "
                         "1 runs them side by side, --np runs them in turn on all ranks")


def run(args: argparse.Namespace) -> int:
    setup_logging(args.log_level)
    cases = load_all()
    if args.report is not None and not args.name:   # report of what is already under --out
        write_report(args.out, args.report)
        return 0
    if args.list or not args.name:
        width = max(map(len, cases))
        for name in sorted(cases):
            c = cases[name]
            print(f"{name:<{width}} issue #{c.issue:<3} {c.description}")
        return 0
    names = sorted(cases) if args.name == "all" else [args.name]
    ok = True
    for name in names:
        np_ = args.np if args.np is not None else cases[name].default_ranks if name in cases else 1
        ok &= run_one(name, args.level, args.out, np_, args.log_level, args.resume, args.ranks_per_run)
    if args.report is not None:
        write_report(args.out, args.report)
    return 0 if ok else 1
