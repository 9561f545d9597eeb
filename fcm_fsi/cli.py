"""Command line of fcm_fsi: ``python -m fcm_fsi COMMAND [options]`` (installed: ``fcm-fsi``).

Every command has its own ``--help``. A first argument that is not a command is a case file:
``python -m fcm_fsi CASE.yaml [options]`` is ``python -m fcm_fsi run CASE.yaml [options]``.
"""
from __future__ import annotations

import argparse
import importlib
import sys

#: command → (module under fcm_fsi.tools, one line for the command list)
COMMANDS = {
    "run": ("run", "run a case file (mpirun -n N for N ranks)"),
    "validate": ("validate", "check a case file and run the pre-run checks, then exit"),
    "verify": ("verify", "verification cases against references: metrics, plots, report"),
    "bench": ("bench", "benchmarks (not tests)"),
    "mesh": ("mesh", "generate a case's gmsh mesh without running it: size, cost, .msh file"),
    "snapshots": ("snapshots", "PNG views of a 3D coupled run (free surface, blocks by damage)"),
    "bond-report": ("bond_report", "how close a bonded structure came to breaking, from a checkpoint"),
    "load-factor": ("load_factor", "DEM pushover: how many times a recorded fluid load breaks a bond"),
    "failure-sequence": ("failure_sequence", "which building member broke when, from a run's bond_breaks.csv"),
    "strength": ("strength", "the sigma_c that makes the blocks' joints as strong as a given concrete"),
}


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m fcm_fsi", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (module, summary) in COMMANDS.items():
        tool = importlib.import_module(f"{__package__}.tools.{module}")
        p = sub.add_parser(name, help=summary, description=tool.__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        tool.add_arguments(p)
        p.set_defaults(handler=tool.run)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (default: the process's arguments), run the command, return its exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in COMMANDS and argv[0] not in ("-h", "--help"):
        argv.insert(0, "run")
    args = build_parser().parse_args(argv)
    return int(args.handler(args) or 0)
