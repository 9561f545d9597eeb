"""What one coupled step changes, kept and put back, and the implicit coupling built on it.

:class:`StepSnapshot` copies the step's start state (the fluid's, the DEM's with its contact
histories, bonds and ledger, the added mass's and the exchange check's) so a step can be
taken again: as two half steps after a failed fluid solve, or as the next pass of the
implicit coupling.

:class:`ImplicitIteration` (``coupling.iterations`` > 1): a fixed-point iteration on the
block velocities at tⁿ⁺¹ (the wall velocity ū the fluid gets ⇄ the result of the DEM
sub-steps), updated between passes as ``coupling.iteration_method`` says (fixed_point.py),
every pass from the same start state (``iqn_mvj`` also carries its inverse Jacobian from step to
step: :meth:`ImplicitIteration.arrays`). The unknown is, per block, the V and Ω × radius of
gyration of the rigid motion its wall nodes get (wall_motion.WallMotion.motion: with
``wall_velocity: mean`` the sub-steps' mean, with ``wall_motion: bonded_cluster`` its
cluster's motion), not the end-of-step v, ω: the fluid never sees those in these modes, so
iterating on them would measure the bonds' ringing, which no pass can converge.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..io.logging import get_logger
from .fixed_point import accelerator

log = get_logger("coupled")


def dem_arrays(system, dem, added) -> dict[str, np.ndarray]:
    """Copies of everything the DEM side carries between steps (DEMSystem.arrays, the added
    mass's last accelerations, the sub-steps' mean velocities), by flat names: checkpoint
    globals and the step snapshot. ``dem`` the DEMSubcycler, ``added`` the AddedMassStage."""
    out = system.arrays()
    out.update(added.arrays())
    if dem.mean_velocity is not None:
        out["coupling__mean_velocity"] = np.concatenate([dem.mean_velocity, dem.mean_omega])
    return out


def load_dem_arrays(system, dem, added, g: dict[str, np.ndarray]) -> None:
    """Inverse of :func:`dem_arrays`."""
    system.load_arrays(g)
    added.load_arrays(g)
    if "coupling__mean_velocity" in g:
        m, nb = g["coupling__mean_velocity"], system.state.nb
        dem.mean_velocity, dem.mean_omega = m[:nb].copy(), m[nb:].copy()
    else:                                  # taken before the first step: no sub-steps' mean yet
        dem.mean_velocity = dem.mean_omega = None


class StepSnapshot:
    """The start state of a coupled step (module docstring), taken at construction.
    ``fluid`` has ``snapshot()``/``restore(s)``; ``dem`` the DEMSubcycler; ``added`` the
    AddedMassStage; ``exchange`` the ExchangeStage; ``implicit`` the ImplicitIteration or None."""

    def __init__(self, fluid, dem, added, exchange, implicit=None) -> None:
        self.fluid, self.dem, self.added, self.exchange, self.implicit = fluid, dem, added, exchange, implicit
        self._fluid = fluid.snapshot()
        self._dem = dem_arrays(dem.system, dem, added)
        self._exchange = exchange.snapshot()
        self._implicit = implicit.arrays() if implicit is not None else None

    def restore(self) -> None:
        """Put the start state back (the snapshot stays valid for another restore)."""
        self.fluid.restore(self._fluid)
        load_dem_arrays(self.dem.system, self.dem, self.added, self._dem)
        self.exchange.restore(self._exchange)
        if self.implicit is not None:
            self.implicit.load_arrays(self._implicit)


class ImplicitIteration:
    """The passes of an implicit step (module docstring). ``coupling`` the case's coupling
    section; ``walls`` the WallMotion; ``gyration`` (nb,) [m] the radii that scale Ω."""

    def __init__(self, coupling, walls, gyration: np.ndarray) -> None:
        self.coupling, self.walls, self.gyration = coupling, walls, gyration
        self.fixed_point = accelerator(coupling.iteration_method, coupling.iteration_relaxation,
                                       coupling.iteration_reuse)
        self.iterations_done, self.residual = 1, 0.0
        self.unconverged = 0          # steps that ended without meeting iteration_tol
        self.history: list[float] = []    # the residual after each pass of the last step

    def unknown(self) -> np.ndarray:
        """The iterated unknown [m/s], flattened: per block V and Ω × radius of gyration."""
        _, V, W = self.walls.motion()
        return np.concatenate([V, W * self.gyration[:, None]]).ravel()

    def run(self, t: float, start: StepSnapshot, one_pass: Callable[[np.ndarray, bool], np.ndarray],
            warm_start: Callable[[np.ndarray], None], flow: Callable[[], np.ndarray], retake: bool = True):
        """Iterate the step from ``start`` at ``t`` [s] until the unknown's change is within
        ``coupling.iteration_tol`` or ``coupling.iterations`` passes are done. ``one_pass(guess,
        retake)`` takes the step with the wall velocity ``guess`` and returns the DEM's load;
        ``retake`` (a later pass keeps the first pass's cut and flow added mass and starts from
        the last pass's flow, ``flow()``, through ``warm_start``) or every pass from scratch.
        Returns the last pass's DEM load."""
        cp = self.coupling
        guess = self.unknown()
        fixed_point = self.fixed_point
        fixed_point.start_step()
        self.history = []
        for k in range(cp.iterations):
            later = k > 0 and retake
            if k:
                last = flow()
                start.restore()
            if later:
                # a later pass differs from the last only in the wall velocity: its flow starts this
                # pass's Newton iteration (on the kept factorisation), and the poses, so the cut, are
                # the last pass's (φ is not: inside the blocks it moves with the wall velocity)
                warm_start(last)
            load = one_pass(guess, later)
            result = self.unknown()
            scale = max(float(np.abs(result).max(initial=0.0)), cp.iteration_velocity)
            self.residual = float(np.abs(result - guess).max(initial=0.0)) / scale
            self.iterations_done = k + 1
            self.history.append(self.residual)
            if self.residual <= cp.iteration_tol:
                break
            if k + 1 < cp.iterations:
                guess = fixed_point.next_guess(guess, result)
        else:
            # the first time as a warning, then at debug level (series.csv: coupling_residual of every step)
            report = log.debug if self.unconverged else log.warning
            self.unconverged += 1
            report("t = %.6g s: the implicit coupling did not converge in %d passes (residual %.2e > "
                   "coupling.iteration_tol %.2e); the step is taken with the last pass (later ones: series.csv, "
                   "coupling_residual). Residuals far above the tolerance in a row precede a blow-up: raise "
                   "coupling.iterations or lower run.cfl", t, cp.iterations, self.residual, cp.iteration_tol)
        fixed_point.end_step(guess, result)
        log.debug("t = %.6g s: coupling residuals %s", t, " ".join(f"{r:.2e}" for r in self.history))
        return load

    def arrays(self) -> dict[str, np.ndarray]:
        """What the iteration carries from step to step (``iqn_mvj``'s inverse Jacobian; nothing
        for the others): checkpoint globals and the step snapshot."""
        return self.fixed_point.arrays()

    def load_arrays(self, g: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`arrays`."""
        self.fixed_point.load_arrays(g)
