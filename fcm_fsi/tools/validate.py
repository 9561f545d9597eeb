"""Check a case file, every resolution level in it, and run the pre-run checks (blocks and
liquid inside the mesh, the mesh's cells and memory against this machine's for the rank
count, time steps), then exit: ``python -m fcm_fsi validate CASE.yaml`` (the same as
``run CASE.yaml --validate``). Exit code 0 when valid, 2 otherwise (the message names the
file, key, value and allowed range)."""
from __future__ import annotations

import argparse

from . import run as run_command


def add_arguments(ap: argparse.ArgumentParser) -> None:
    run_command.add_case_arguments(ap)


def run(args: argparse.Namespace) -> int:
    return run_command.run(argparse.Namespace(**vars(args), validate=True, output=None, restart=None))
