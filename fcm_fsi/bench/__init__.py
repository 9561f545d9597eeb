"""Benchmarks (not tests), one module each: `python -m fcm_fsi bench NAME` (fcm_fsi/tools/bench.py)."""
