"""fcm_fsi: finite-cover fluid–structure interaction with a DEM of bonded rigid blocks.

Python API (docs/python-api.md): ``Case.from_yaml(path, overrides)``, ``Case.from_dict(data)``,
``run(case, output=..., on_step=...)`` returning the time series as numpy arrays."""
from .api import Case, run

__all__ = ["Case", "run"]
__version__ = "0.1.0"
