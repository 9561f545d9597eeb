"""Rank-aware logging: rank 0 logs at the chosen level, other ranks only warnings.

ffcx calls ``logging.basicConfig()`` on import, so the ``fcm_fsi`` logger gets its own
handler and does not propagate to the root logger.
"""
from __future__ import annotations

import logging
import sys

LOGGER_NAME = "fcm_fsi"


def get_logger(name: str = "") -> logging.Logger:
    """Logger ``fcm_fsi`` or a child of it (``fcm_fsi.<name>``)."""
    return logging.getLogger(f"{LOGGER_NAME}.{name}" if name else LOGGER_NAME)


def setup_logging(level: str = "INFO", rank: int | None = None, logfile: str | None = None) -> logging.Logger:
    """Configure the ``fcm_fsi`` logger; call once per process (idempotent)."""
    if rank is None:
        from mpi4py import MPI
        rank = MPI.COMM_WORLD.rank
    logger = logging.getLogger(LOGGER_NAME)
    # ffcx's basicConfig gives the root logger a handler, and every JIT build (cffi →
    # distutils) sets the root level to INFO, printing compiler command lines: keep the root
    # handlers to warnings (a handler's level is not touched by distutils)
    logging.basicConfig()            # no-op when ffcx already did it; makes a later call a no-op
    for h in logging.getLogger().handlers:
        h.setLevel(logging.WARNING)
    for h in list(logger.handlers):
        logger.removeHandler(h)
    logger.propagate = False
    logger.setLevel(getattr(logging, level.upper(), logging.INFO) if rank == 0 else logging.WARNING)
    fmt = logging.Formatter("%(asctime)s %(levelname)-7s %(message)s" if rank == 0
                            else f"%(asctime)s %(levelname)-7s [rank {rank}] %(message)s", "%H:%M:%S")
    handler = logging.StreamHandler(sys.stdout if rank == 0 else sys.stderr)
    handler.setFormatter(fmt)
    logger.addHandler(handler)
    if logfile and rank == 0:
        fh = logging.FileHandler(logfile, mode="a")
        fh.setFormatter(fmt)
        logger.addHandler(fh)
    return logger
