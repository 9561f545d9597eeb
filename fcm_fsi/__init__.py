"""fcm_fsi: finite-cover fluid–structure interaction with a DEM of bonded rigid blocks.

Python API (docs/python-api.md): ``Case.from_yaml(path, overrides)``, ``Case.from_dict(data)``,
``run(case, output=..., on_step=...)`` returning the time series as numpy arrays."""
import os

from .api import Case, run

# One PT-Scotch thread, set before any mesh is made, for every entry point (CLI, API, verification,
# benchmarks). dolfinx partitions each mesh with PT-Scotch, which runs one thread per core unless
# SCOTCH_PTHREAD_NUMBER says otherwise, and its threaded partition differs from run to run: so did
# every sum over a rank's cells, at round-off, and a run's results with it. A user's setting is kept.
os.environ.setdefault("SCOTCH_PTHREAD_NUMBER", "1")

__all__ = ["Case", "run"]
__version__ = "0.1.0"
