"""Run a case file: ``mpirun -n 2 python -m fcm_fsi run CASE.yaml [options]``
(``python -m fcm_fsi CASE.yaml [options]`` is the same).

Exit codes: 0 success, 2 bad input (case file, override, checkpoint), 3 the run diverged
or a solver failed (the last good checkpoint is kept), 4 stopped on request (STOP file,
SIGTERM/SIGUSR1) with a checkpoint.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_BAD_INPUT = 2
EXIT_DIVERGED = 3
EXIT_STOPPED = 4        # stopped on request (STOP file, SIGTERM/SIGUSR1) with a checkpoint

LOG_LEVELS = ["DEBUG", "INFO", "WARNING", "ERROR"]


def add_case_arguments(ap: argparse.ArgumentParser) -> None:
    """The arguments ``run`` and ``validate`` share: the case file and its overrides."""
    ap.add_argument("case", type=Path, help="case file (YAML); see docs/case-reference.md")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                    help="override a case value, e.g. --set run.dt=1e-3 (repeatable)")
    ap.add_argument("--log-level", default="INFO", choices=LOG_LEVELS)


def add_arguments(ap: argparse.ArgumentParser) -> None:
    add_case_arguments(ap)
    ap.add_argument("--output", type=Path, default=None, help="output folder (default: output.directory of the case)")
    ap.add_argument("--restart", default=None, metavar="CHECKPOINT", help="continue from this checkpoint.h5")
    ap.add_argument("--validate", action="store_true",
                    help="check the case file and run the pre-run checks, then exit (the same as `validate`)")


def reference_blas_loaded(maps: str | None = None) -> bool:
    """True when this process runs on Debian's reference BLAS (``.../blas/libblas.so.3``) and
    no optimised one (OpenBLAS, BLIS, MKL) — direct solves are then ≈ 3× slower
    (docs/performance.md). ``maps``: the text of /proc/self/maps (read when None)."""
    if maps is None:
        try:
            maps = Path("/proc/self/maps").read_text()
        except OSError:
            return False
    libs = {line.split()[-1] for line in maps.splitlines() if ".so" in line}
    reference = any("/blas/libblas.so" in lib for lib in libs)
    optimised = any(k in lib for lib in libs for k in ("openblas", "blis", "mkl"))
    return reference and not optimised


def run_case(case, out: Path, comm, restart: str | None, case_dir: Path) -> None:
    """Run the case on the shared time loop (fcm_fsi/api.py)."""
    from ..api import build_model
    from ..simulation.loop import TimeLoop
    TimeLoop(case, build_model(case, comm, out, restart, case_dir), out, comm, restart).run()


def run(args: argparse.Namespace) -> int:
    from mpi4py import MPI

    from ..config import ConfigError, load_case
    from ..io.logging import setup_logging
    comm = MPI.COMM_WORLD
    log = setup_logging(args.log_level, comm.rank)
    from ..preflight import run_checks
    try:
        case = load_case(args.case, args.set)
        estimate = run_checks(case, comm, log)       # geometry, memory, time steps (collective)
    except ConfigError as err:
        if comm.rank == 0:
            message = str(err)
            print(f"error: {message if message.startswith(str(args.case)) else f'{args.case}: {message}'}",
                  file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.validate:
        if comm.rank == 0:
            size = "" if estimate is None else (f"; mesh ≈ {estimate.cells:.3g} cells, {estimate.unknowns:.3g} "
                                                f"unknowns, ≈ {estimate.bytes_per_rank(comm.size) / 1e9:.2g} GB "
                                                f"per rank on {comm.size}")
            print(f"{args.case}: valid ({case.physics} case '{case.name}'{size})")
        return 0
    out = args.output or Path(case.output.directory)
    from ..api import write_resolved_case
    write_resolved_case(case, out, comm.rank)
    comm.barrier()
    log.info("case %s (%s) on %d rank(s) -> %s", case.name, case.physics, comm.size, out)
    from ..simulation.loop import SimulationDiverged, StopRequested  # imports PETSc, and with it the BLAS
    if reference_blas_loaded():
        log.warning("running on the reference BLAS: direct (MUMPS) solves are about 3x slower; "
                    "install libopenblas0-serial (.ci/setup.sh, docs/performance.md)")
    try:
        run_case(case, out, comm, args.restart, args.case.resolve().parent)
    except ConfigError as err:   # found while setting the case up: name the file too
        if comm.rank == 0:
            print(f"error: {args.case}: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (SimulationDiverged, FloatingPointError) as err:
        log.error("run stopped: %s", err)
        return EXIT_DIVERGED
    except StopRequested as err:
        log.warning("%s", err)
        return EXIT_STOPPED
    return 0
