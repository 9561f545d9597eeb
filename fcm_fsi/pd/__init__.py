"""Peridynamic solids (docs/peridynamics.md): bond-based PD in the dual-horizon form (eqs 2–4,
9–11 of the seed paper). ``material``: micromodulus, critical stretch, Weibull G0, volume
correction, stable step; ``lattice``: points; ``neighbours``: bonds by cell binning and the
pre-notch filter; ``forces``: the bond kernels; ``system``: the state and the velocity-Verlet
step; ``output``: particles for ParaView. Each Numba kernel has a NumPy twin (``reference.py``)."""
