"""fcm_fsi: finite-cover fluid–structure interaction with a DEM of bonded rigid blocks."""
__version__ = "0.1.0"
