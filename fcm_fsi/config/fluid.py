"""Stabilized Navier–Stokes fluid (section ``fluid``; SPEC eqs 1–10). Owned by the fluid solver."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError
from .petsc import check_petsc_options


@dataclass(frozen=True, kw_only=True)
class BoundaryCondition:
    """One boundary condition on a plane of the mesh box, named by axis: ``xmin`` is the plane
    x = mesh.lower[0], ``xmax`` the plane x = mesh.upper[0], then ``ymin``, ``ymax`` and, in 3D,
    ``zmin``, ``zmax`` (for every mesh kind; with z up, ``zmin`` is the ground and ``zmax`` the
    lid). The former names ``left right bottom top front back`` (xmin … zmax) are refused with
    the axis name.

    The Schäfer–Turek channels of the benchmarks (:mod:`fcm_fsi.mesh.channel`) name their
    boundaries ``inlet``, ``outlet``, ``walls``, ``cylinder``.
    """

    boundary: str = param(doc="the mesh plane: xmin, xmax, ymin, ymax, and in 3D zmin, zmax")
    kind: Literal["velocity", "parabolic_inflow", "no_slip", "slip", "do_nothing"] = param(
        doc="velocity: u = value; parabolic_inflow: u = max_speed·Π 4s(L−s)/L² along the inward normal "
            "(s across the boundary's bounding box); no_slip: u = 0; slip: u·n = 0 on an axis-aligned "
            "boundary; do_nothing: natural outflow (σ·n = 0)")
    value: tuple[float, ...] = param((0.0, 0.0), unit="m/s", doc="velocity vector for kind = velocity")
    max_speed: float = param(1.0, unit="m/s", doc="centre-line speed of the parabolic inflow", ge=0)
    ramp_time: float = param(0.0, unit="s", doc="velocity/parabolic inflow ramped by (1 − cos(π t/ramp))/2 "
                                               "for t < ramp_time (0 = no ramp)", ge=0)


@dataclass(frozen=True, kw_only=True)
class DampingZone:
    """A sponge layer (numerical beach) along one axis: the momentum sink ρ σ u with
    σ = rate·ξ², ξ = (s − start)/(end − start) clipped to [0, 1] and s the coordinate along
    ``axis``. It absorbs the waves a floating or moving body radiates before they reflect
    from the wall at ``end``; outside [start, end] the flow is untouched."""

    axis: Literal["x", "y", "z"] = param(doc="coordinate the layer runs along")
    start: float = param(unit="m", doc="coordinate where the damping begins (σ = 0)")
    end: float = param(unit="m", doc="coordinate where σ reaches ``rate`` (usually the wall); beyond it σ = rate")
    rate: float = param(unit="1/s", doc="largest damping rate σ", gt=0)


@dataclass(frozen=True, kw_only=True)
class StabilizationConfig:
    """Switches of the residual-based terms of eq 5 (τ from eqs 6–10)."""

    supg: bool = param(True, doc="streamline-upwind Petrov–Galerkin term (τ_supg, eq 6)")
    pspg: bool = param(True, doc="pressure-stabilizing term (τ_pspg = τ_supg, eq 7); needed for P1/P1")
    lsic: bool = param(True, doc="least-squares incompressibility term (τ_cont, eqs 8–10)")
    time_term: bool = param(True, doc="include (2/Δt)² in τ_supg (eq 6)")
    viscous_reconstruction: bool = param(
        True, doc="in the strong residual use ∇·(2μ G), G = lumped L2 projection of ε(u) onto P1, instead of "
                  "∇·(2μ ε(u)) which vanishes for P1 (restores consistency, hence 2nd order)")


@dataclass(frozen=True, kw_only=True)
class FluidConfig:
    """Single- or two-phase incompressible Newtonian fluid on P1/P1 (eq 5)."""

    density: float = param(1000.0, unit="kg/m^3", doc="density of the (liquid) fluid", gt=0)
    viscosity: float = param(1.0e-3, unit="Pa s", doc="dynamic viscosity of the (liquid) fluid", gt=0)
    gas_density: float = param(1.2, unit="kg/m^3", doc="density of the second phase (φ = 0) for two-phase runs", gt=0)
    gas_viscosity: float = param(1.8e-5, unit="Pa s", doc="dynamic viscosity of the second phase (φ = 0)", gt=0)
    gravity: tuple[float, ...] = param((0.0, 0.0), unit="m/s^2", doc="body force per unit mass f (eq 1), e.g. [0, -9.81]")
    boundaries: tuple[BoundaryCondition, ...] = param(default_factory=tuple,
                                                      doc="boundary conditions; boundaries not listed are do-nothing")
    damping_zones: tuple[DampingZone, ...] = param(default_factory=tuple,
                                                   doc="sponge layers (numerical beaches) absorbing waves near walls")
    theta: float = param(0.5, doc="time scheme: 0.5 = Crank–Nicolson, 1 = backward Euler (pseudo-time to steady states)",
                         ge=0.5, le=1.0)
    startup_steps: int = param(2, doc="first steps made of two backward-Euler half steps (Rannacher start-up; "
                                         "damps incompatible initial data that Crank–Nicolson keeps)", ge=0)
    stabilization: StabilizationConfig = param(default_factory=StabilizationConfig, doc="stabilization terms")
    nonlinear: Literal["newton", "picard", "linearised"] = param(
        "newton", doc="newton: exact Jacobian with τ frozen per iteration, iterated to rtol/atol; picard: advecting "
                      "velocity frozen (Oseen), iterated; linearised: one Oseen solve per step with the advecting "
                      "velocity and τ extrapolated from the last two steps, (1 + θ)uⁿ − θuⁿ⁻¹ (second order, no "
                      "iteration: rtol, atol only decide whether a solve is needed)")
    krylov_start: Literal["zero", "extrapolated"] = param(
        "zero", doc="with nonlinear: linearised and a Krylov solver: where each step's solve starts. zero: from "
                    "nothing; extrapolated: from the update of the last two steps extrapolated in time (fewer "
                    "iterations on the 2D dam break, 21.7 instead of 26.1 per step; more, and larger errors in the "
                    "weakly weighted modes the stopping rule lets through, on the 3D tsunami: docs/performance.md)")
    rtol: float = param(1.0e-8, doc="nonlinear stop: ‖R‖ ≤ max(rtol·‖R₀‖, atol) each step", gt=0, lt=1)
    atol: float = param(1.0e-10, doc="absolute residual tolerance of the nonlinear iteration; a Krylov solve that "
                                     "stops short of its rtol (iteration limit) is accepted when its residual is below it",
                        gt=0)
    tau_freeze: float = param(0.0, doc="keep τ (eqs 6–10) fixed for the rest of a step once the residual has dropped "
                                      "by this factor (0 = recompute every iteration: the step solves the equations "
                                      "with τ(uⁿ⁺¹) exactly; e.g. 1e-3 stops Newton cycling when the switch of eq 10 "
                                      "flips, τ then lags the converged iterate slightly)", ge=0, lt=1)
    backflow: float = param(1.0, doc="β of the directional do-nothing condition: on do_nothing boundaries the "
                                     "residual gets −β ∫ ½ ρ min(u·n, 0) u·w ds, which removes the kinetic energy "
                                     "that flow entering through an open boundary would otherwise bring in unchecked "
                                     "(backflow instability; zero where the flow leaves); 0 = plain do-nothing",
                            ge=0, le=10)
    line_search: int = param(4, doc="Newton/Picard globalisation: when a full update raises the residual norm, halve "
                                    "the update up to this many times (0 = off); converging steps never trigger it",
                             ge=0, le=20)
    reuse_preconditioner: bool | None = param(
        None, doc="build the preconditioner once per time step (first nonlinear iteration) and reuse it for "
                  "the later iterations of the step: saves the AMG/ILU set-up when the Jacobian changes little "
                  "(docs/performance.md); the Krylov tolerance is unchanged, so the step converges to the same "
                  "tolerance. null = automatic: on for Krylov solvers, off for a direct solve (ksp_type preonly), "
                  "where it would turn Newton into a chord iteration")
    preconditioner_steps: int = param(
        1, doc="with reuse_preconditioner: keep the preconditioner for up to this many time steps, not just "
               "within one (e.g. an LU factorisation as GMRES preconditioner: factorise once, then a few "
               "Krylov iterations per solve while the Jacobian drifts). It is rebuilt earlier when a solve "
               "needed more than preconditioner_max_iterations, and a solve that fails with the old one is "
               "repeated with a fresh one; the Krylov tolerance is unchanged. 1 = rebuild every step", ge=1, le=1000)
    preconditioner_max_iterations: int = param(
        30, doc="Krylov iterations above which a kept preconditioner (preconditioner_steps > 1) is rebuilt "
                "at the next solve", ge=1, le=10000)
    max_iterations: int = param(25, doc="nonlinear iterations per step before the run stops with an error", ge=1)
    quadrature_degree: int = param(0, doc="quadrature degree of the NS forms (0 = automatic: 2, or 3 with field ρ/μ); in coupled "
                                   "runs the cells the structure cuts use the moment-fitted rule instead", ge=0, le=8)
    well_balanced: bool | None = param(
        None, doc="two-phase runs: carry the gradient part of ρ f as a P2 static pressure Π, p = p' + Π "
                  "(fluid/hydrostatic.py), so that a layered fluid at rest is an exact discrete solution; "
                  "costs one P2 Poisson solve per step. null = automatic: on without blocks, off in coupled "
                  "runs (not yet validated with the cut domain, docs/two-phase.md); false = the plain P1 "
                  "pressure (spurious currents at the density jump)")
    mass_consistent_convection: bool = param(
        False, doc="two-phase runs: add ½(∂ρ/∂t + ∇·(ρu))·u·w to the momentum equation (the "
                   "variable-density form of Temam's term, Guermond & Quartapelle 2000). ρ(φ) of the "
                   "phase field does not obey the mass equation exactly (interface sharpening, clipping, "
                   "volume correction); without the term that mismatch feeds kinetic energy ½|u|²·(mass "
                   "defect) into the flow, most strongly in the air next to thin water films. Zero where "
                   "ρ follows the mass equation, so consistent")
    pressure_reference: tuple[float, ...] | None = param(
        None, unit="m", doc="point where p = 0 is pinned when no boundary is do_nothing (default: mesh lower corner)")
    petsc: dict[str, str | int | float | bool] = param(
        default_factory=dict,
        doc="PETSc options of the monolithic (u, p) solve, prefix ns_; empty = automatic: MUMPS LU in 2D, "
            "in 3D FGMRES + Schur field split with GAMG on the velocity block and BoomerAMG on the Schur "
            "complement (fcm_fsi.fluid.solvers.SCHUR_GAMG; BoomerAMG on both blocks, SCHUR_AMG, on a cut "
            "fluid domain); blocks addressed as fieldsplit_u_*, fieldsplit_p_*")

    def __post_init__(self) -> None:
        names = [bc.boundary for bc in self.boundaries]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ConfigError(f"key 'fluid.boundaries': boundary {dupes[0]!r} has more than one condition")
        if len(self.gravity) not in (2, 3):
            raise ConfigError(f"key 'fluid.gravity' = {list(self.gravity)} must have 2 or 3 entries")
        for i, z in enumerate(self.damping_zones):
            if z.start == z.end:
                raise ConfigError(f"key 'fluid.damping_zones[{i}]': start = end = {z.start:g} m; the layer needs "
                                  f"a width (start ≠ end)")
            if "xyz".index(z.axis) >= len(self.gravity):
                raise ConfigError(f"key 'fluid.damping_zones[{i}].axis' = {z.axis!r}: allowed x, y"
                                  + (", z" if len(self.gravity) == 3 else f" in {len(self.gravity)}D"))
        for i, bc in enumerate(self.boundaries):
            if bc.kind == "velocity" and len(bc.value) not in (2, 3):
                raise ConfigError(f"key 'fluid.boundaries[{i}].value' = {list(bc.value)} must have 2 or 3 entries")
        check_petsc_options("fluid.petsc", self.petsc)
