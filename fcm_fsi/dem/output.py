"""DEM output: spheres as VTK PolyData (.vtp, binary inline) + a .pvd time collection for
ParaView (the writers: io/vtp.py; checkpoints: simulation/dem_model.py through the shared
io/checkpoint.py).

ParaView: open ``spheres.pvd``, apply the *Glyph* filter (glyph type Sphere, scale array
``radius``, scale factor 2 — ParaView's unit sphere glyph has radius 0.5) and colour by
``block``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.vtp import write_points_vtp
from .state import DEMState

__all__ = ["write_vtp"]


def write_vtp(path: Path, state: DEMState, extra: dict[str, np.ndarray] | None = None) -> None:
    """One PolyData file: a vertex per sphere with radius, block id and velocity, and the
    per-sphere arrays of ``extra`` (name → (ns,) or (ns, 3))."""
    vel = state.vel[state.sph_block] + np.cross(state.omega[state.sph_block],
                                                  state.sph_pos - state.pos[state.sph_block])
    data = {"radius": state.sph_radius, "block": state.sph_block.astype(np.int64), "velocity": vel,
            "material": state.sph_material.astype(np.int64), **(extra or {})}
    write_points_vtp(path, state.sph_pos, data, scalars="radius")
