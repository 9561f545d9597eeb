"""Prescribed (kinematic) velocity fields for phase-field-only cases."""
from __future__ import annotations

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from ..config.phase_field import PrescribedVelocity


def velocity_values(cfg: PrescribedVelocity, x: np.ndarray, gdim: int) -> np.ndarray:
    """u(x) [m/s] as (gdim, npts): rigid rotation ω ẑ × (x − c), or a uniform vector."""
    u = np.zeros((gdim, x.shape[1]))
    if cfg.kind == "rotation":
        u[0] = -cfg.omega * (x[1] - cfg.center[1])
        u[1] = cfg.omega * (x[0] - cfg.center[0])
    else:
        if len(cfg.value) != gdim:
            from ..config.loader import ConfigError
            raise ConfigError(f"key 'phase_field.velocity.value' must have {gdim} entries")
        u[:] = np.array(cfg.value)[:, None]
    return u


def prescribed_velocity(msh, cfg: PrescribedVelocity) -> tuple[fem.Function, float]:
    """P1 vector Function of the prescribed field and its global max speed [m/s]."""
    gdim = msh.geometry.dim
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
    u = fem.Function(V, name="velocity")
    u.interpolate(lambda x: velocity_values(cfg, x, gdim))
    u.x.scatter_forward()
    speed = np.sqrt((u.x.array.reshape(-1, gdim) ** 2).sum(axis=1))
    umax = msh.comm.allreduce(float(speed.max()) if speed.size else 0.0, op=MPI.MAX)
    return u, umax
