"""Benchmarks (not tests): ``python -m fcm_fsi bench NAME [options]``, NAME a module of
fcm_fsi/bench/; ``python -m fcm_fsi bench NAME --help`` shows its options. Results and the
commands that produced them are in docs/performance.md.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from .. import bench


def available() -> list[str]:
    """The benchmarks: the public modules of fcm_fsi.bench."""
    return sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_"))


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("name", nargs="?", metavar="NAME", help=f"the benchmark: {', '.join(available())}")
    ap.add_argument("options", nargs=argparse.REMAINDER, help="the benchmark's own options (NAME --help)")
    ap.add_argument("--list", action="store_true", help="list the benchmarks and exit")


def run(args: argparse.Namespace) -> int:
    if args.list or args.name is None:
        print("available: " + ", ".join(available()))
        return 0
    if args.name not in available():
        print(f"error: unknown benchmark {args.name!r}; available: {', '.join(available())}", file=sys.stderr)
        return 2
    return int(importlib.import_module(f"{bench.__name__}.{args.name}").run(args.options) or 0)
