"""The stabilized Navier–Stokes forms as small pure functions of :class:`FormParts` (SPEC §1,
paper eqs 5–10; the weak form is written out in :mod:`.navier_stokes`): the momentum
residual, the SUPG/PSPG and LSIC terms, the damping zones, the open boundaries' terms, the
stabilization parameters τ and the cell size h."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem

from ..config.fluid import FluidConfig


@dataclass
class FormParts:
    """The symbols a term needs: trial state, previous state, tests, properties, measure."""

    u: ufl.core.expr.Expr          # velocity at t^{n+1}
    p: ufl.core.expr.Expr          # pressure (at t^{n+1}, acts as p^{n+θ}); p' + Π with a static part
    u_n: ufl.core.expr.Expr        # velocity at t^n
    u_theta: ufl.core.expr.Expr    # θ u + (1 − θ) uⁿ
    a: ufl.core.expr.Expr          # advecting velocity
    w: ufl.core.expr.Expr          # momentum test function
    q: ufl.core.expr.Expr          # continuity test function
    rho: ufl.core.expr.Expr        # density (constant or Function)
    mu: ufl.core.expr.Expr         # dynamic viscosity (constant or Function)
    f: ufl.core.expr.Expr          # body force per unit mass
    dt: fem.Constant
    dx: ufl.Measure
    tau_supg: fem.Function
    tau_cont: fem.Function
    strain: fem.Function | None = None   # P1 reconstruction of ε(u_θ) for the strong residual
    rho_pspg: ufl.core.expr.Expr | None = None  # density of the PSPG test ∇q/ρ (default: rho)
    sigma: ufl.core.expr.Expr | None = None     # sponge-layer damping rate σ(x) [1/s] (None: no layers)
    mu_cell: ufl.core.expr.Expr | None = None   # cell-wise (DG0) viscosity beside rho_pspg (None: mu)

    @property
    def cell_density(self):
        """ρ for terms that need it constant per cell: the cell-wise ``rho_pspg`` when given, else ``rho``."""
        return self.rho_pspg if self.rho_pspg is not None else self.rho

    @property
    def cell_viscosity(self):
        """μ for terms that need it constant per cell: ``mu_cell`` when given, else ``mu``."""
        return self.mu_cell if self.mu_cell is not None else self.mu


def epsilon(u):
    """Rate-of-strain tensor ε(u) (eq 4)."""
    return ufl.sym(ufl.grad(u))


def momentum_residual(s: FormParts):
    """Strong momentum residual R_M of eq 5.

    ∇·ε(u) of a P1 field vanishes inside cells; with ``s.strain`` (the P1 projection G of
    ε(u_θ), lagged one nonlinear iteration) the viscous term is ∇·(2μ G) and R_M vanishes
    for the exact solution up to O(h²).
    """
    strain = s.strain if s.strain is not None else epsilon(s.u_theta)
    r = (s.rho * ((s.u - s.u_n) / s.dt + ufl.grad(s.u_theta) * s.a - s.f)
         - ufl.div(2 * s.mu * strain) + ufl.grad(s.p))
    return r if s.sigma is None else r + s.rho * s.sigma * s.u_theta


def galerkin_residual(s: FormParts):
    """Galerkin part of eq 5."""
    return (ufl.inner(s.rho * ((s.u - s.u_n) / s.dt + ufl.grad(s.u_theta) * s.a - s.f), s.w) * s.dx
            + ufl.inner(2 * s.mu * epsilon(s.u_theta), epsilon(s.w)) * s.dx
            - s.p * ufl.div(s.w) * s.dx + s.q * ufl.div(s.u) * s.dx)


def damping_rate(mesh, zones):
    """σ(x) [1/s] of the sponge layers (config.fluid.DampingZone): Σ rate·ξ²,
    ξ = (x_axis − start)/(end − start) clipped to [0, 1]; None without layers."""
    if not zones:
        return None
    x = ufl.SpatialCoordinate(mesh)
    sigma = 0
    for z in zones:
        xi = (x["xyz".index(z.axis)] - z.start) / (z.end - z.start)
        sigma = sigma + z.rate * ufl.max_value(0.0, ufl.min_value(1.0, xi)) ** 2
    return sigma


def damping_residual(s: FormParts) -> ufl.Form:
    """Sponge layers: the momentum sink ∫ ρ σ(x) u_θ·w dx (also in the strong residual R_M,
    so the stabilisation stays consistent; at rest it vanishes)."""
    return s.rho * s.sigma * ufl.inner(s.u_theta, s.w) * s.dx


def do_nothing_correction(s: FormParts, ds):
    """−∫ μ (∇u_θ)ᵀn·w ds on natural boundaries: turns σ·n = 0 of the symmetric form into
    (μ∇u − pI)·n = 0, the usual do-nothing outflow that Poiseuille flow satisfies."""
    n = ufl.FacetNormal(s.u.ufl_domain())
    return -ufl.inner(s.mu * ufl.grad(s.u_theta).T * n, s.w) * ds


def backflow_residual(s: FormParts, ds, beta: float):
    """Directional do-nothing (Braack & Mucha 2014): −β ∫ ½ ρ min(a·n, 0) u_θ·w ds on natural
    boundaries. Where fluid enters (a·n < 0) the energy balance of the do-nothing condition gains
    the uncontrolled flux −½ρ(a·n)|u|²; this term takes it out again. Where the flow leaves it is zero,
    so outflow solutions (Poiseuille, the Schäfer–Turek channel) are unchanged."""
    n = ufl.FacetNormal(s.u.ufl_domain())
    inflow = ufl.min_value(ufl.dot(s.a, n), 0.0)
    return -beta * 0.5 * s.rho * inflow * ufl.inner(s.u_theta, s.w) * ds


def supg_pspg_residual(s: FormParts, supg: bool, pspg: bool):
    """SUPG and PSPG terms of eq 5, τ_pspg = τ_supg (eq 7)."""
    test = 0
    if supg:
        test = test + ufl.grad(s.w) * s.a
    if pspg:
        test = test + ufl.grad(s.q) / s.cell_density
    if test == 0:
        return None
    return s.tau_supg * ufl.inner(test, momentum_residual(s)) * s.dx


def lsic_residual(s: FormParts):
    """Least-squares incompressibility ('τ_cont') term of eq 5."""
    return s.tau_cont * s.rho * ufl.div(s.w) * ufl.div(s.u) * s.dx


def tau_expressions(a, rho, mu, h, dt, time_term: bool):
    """τ_supg (eq 6) and τ_cont (eqs 8–10) as UFL expressions of cell-wise quantities."""
    nu = mu / rho
    speed = ufl.sqrt(ufl.inner(a, a))
    inv2 = (2 * speed / h) ** 2 + (4 * nu / h ** 2) ** 2
    if time_term:
        inv2 = inv2 + (2 / dt) ** 2
    tau_supg = 1 / ufl.sqrt(inv2)
    re_e = speed * h / (2 * nu)
    xi = ufl.conditional(ufl.le(re_e, 3.0), re_e / 3.0, 1.0)
    tau_cont = h / 2 * speed * xi
    return tau_supg, tau_cont


def quadrature_degree(config: FluidConfig, field_properties: bool) -> int:
    """Degree of the NS forms' rule: ``config.quadrature_degree``, or automatic: 2, exact for
    the P1 products with constant ρ, μ; 3 with field (P1) ρ, μ."""
    return config.quadrature_degree or (3 if field_properties else 2)


def cell_size(mesh) -> fem.Function:
    """Representative element length h_e (DG0): diameter of the disc/ball of the cell's area/volume."""
    tdim = mesh.topology.dim
    V0 = fem.FunctionSpace(mesh, ("DG", 0))
    h = fem.Function(V0, name="h")
    x = mesh.geometry.x
    ncells = mesh.topology.index_map(tdim).size_local + mesh.topology.index_map(tdim).num_ghosts
    nodes = mesh.geometry.dofmap.array.reshape(ncells, -1)[:, : tdim + 1]
    edges = x[nodes[:, 1:], :tdim] - x[nodes[:, :1], :tdim]
    vol = np.abs(np.linalg.det(edges)) / (2.0 if tdim == 2 else 6.0)
    diam = np.sqrt(4 * vol / np.pi) if tdim == 2 else np.cbrt(6 * vol / np.pi)
    dofs = V0.dofmap.list.array.reshape(ncells, -1)[:, 0]
    h.x.array[dofs] = diam
    return h
