"""Peridynamic solids (docs/peridynamics.md): bond-based and ordinary state-based PD in the
dual-horizon form (eqs 2–11 of the seed paper). ``material``: micromodulus, K and G, influence,
weighted volume, critical stretch, Weibull G0, volume correction, stable step; ``lattice`` and
``particles`` (tetrahedron centroids): points; ``neighbours``: bonds by cell binning and the
pre-notch filter; ``forces``: the bond-based kernels; ``state``: the state-based kernels;
``system``: the laws, the state and the velocity-Verlet step; ``builder``: a body from the case.
Each Numba kernel has a NumPy twin (``reference.py``)."""
