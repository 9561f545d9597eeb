"""Steady states by pseudo-time marching of the Navier–Stokes solver."""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from ..io.logging import get_logger
from .navier_stokes import NavierStokes, NonlinearSolveError

log = get_logger("fluid")


def march_to_steady(ns: NavierStokes, tol: float, max_steps: int, growth: float = 1.0,
                    dt_max: float = np.inf) -> int:
    """Pseudo-time march until max|u^{n+1} − uⁿ|/(Δt·max|u|) ≤ tol (1/s); returns steps taken.

    Use θ = 1 and τ without the Δt term (``stabilization.time_term: false``) so the steady
    state does not depend on Δt. Δt grows by ``growth`` per step up to ``dt_max``
    (switched evolution relaxation); a failed step is retried once with Δt/4. Collective.
    """
    rate = np.inf
    for k in range(1, max_steps + 1):
        try:
            ns.step()
        except NonlinearSolveError:
            ns.U.x.array[:] = ns.U_n.x.array
            ns.t -= float(ns.dt.value)
            ns.step_count -= 1
            ns.dt.value = float(ns.dt.value) / 4
            log.info("steady march: step %d failed, retrying with dt = %g", k, float(ns.dt.value))
            ns.step()
        rate = _change_rate(ns)
        log.debug("steady march step %d (dt %g): relative change rate %.3e", k, float(ns.dt.value), rate)
        if rate <= tol:
            return k
        ns.dt.value = min(float(ns.dt.value) * growth, dt_max)
    raise NonlinearSolveError(ns.step_count, ns.t, [rate],
                              f"no steady state within {max_steps} steps (change rate {rate:.3e} > {tol:g})")


def _change_rate(ns: NavierStokes) -> float:
    """max|u^{n+1} − uⁿ| / (Δt max|u^{n+1}|) over all ranks (1/s)."""
    du = ns.U.x.array[ns.V_map] - ns.U_n.x.array[ns.V_map]
    local = np.array([np.abs(du).max(initial=0.0), np.abs(ns.U.x.array[ns.V_map]).max(initial=0.0)])
    glob = np.empty_like(local)
    ns.comm.Allreduce(local, glob, op=MPI.MAX)
    return float(glob[0] / (float(ns.dt.value) * max(glob[1], 1e-300)))
