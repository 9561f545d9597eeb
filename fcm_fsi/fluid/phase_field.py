"""Conservative Allen–Cahn phase field (paper eqs 11, 14–17; Chiu & Lin 2011).

    φ_t + u·∇φ = γ ∇·(ε∇φ − φ(1−φ) n),   n = ∇φ/|∇φ|          (conservative, eq 11)
    φ_t + u·∇φ = γ (εΔφ − φ(1−φ)(1−2φ)/ε)                      (classical Allen–Cahn)

φ = 1 liquid, 0 gas, 0.5 interface; ε is the interface width [m] and γ a velocity
[m/s]. In the paper's notation δ = ε and the paper's mobility is γε. The equilibrium
profile is φ = 1/(1 + exp(−d/ε)) with d the signed distance (positive in the liquid).

Discretisation: P1, Crank–Nicolson for the linear terms, the sharpening flux
φ(1−φ)n (or the Allen–Cahn reaction) explicit at φ* = 3/2 φⁿ − 1/2 φⁿ⁻¹ (second order,
linear system per step), SUPG with τ_φ of eq 15. With a divergence-free velocity and
no inflow of liquid, ∫φ dx is conserved to solver tolerance by the conservative form
(test function 1 removes every term but the boundary flux).

Volume correction (eqs 16–17): V = |{φ ≥ 1/2}| and A = |{φ = 1/2}| measured exactly on
the P1 field (fcm/cut.py); the interface is shifted by L = (V − V₀)/A by shifting the
profile's signed distance d = ε ln(φ/(1−φ)) → d − L. On a cut domain (coupled runs) V and
A are those of the fluid part (:meth:`PhaseField.volume`), because φ lives on the whole mesh
and the water that diffuses into a body's fictitious interior is not water of the flow.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem.petsc import assemble_matrix, assemble_vector, create_vector
from mpi4py import MPI
from petsc4py import PETSc

from .. import jit
from ..config.loader import ConfigError
from ..config.phase_field import InitialShape, PhaseFieldConfig
from ..fcm.cut import cut_measures
from ..mesh.build import cell_sizes
from .initial import signed_distance
from .solvers import make_ksp
from .solvers import solve as solve_ksp

# Quadrature degree per form: with the P1 nodal normal the conservative integrands are
# polynomials of degree ≤ 3 (exact at degree 3); the classical reaction term
# φ³·w needs 4. τ_φ (SUPG) is not polynomial: the degree stays fixed (FFCx would pick ~100 points).
QUADRATURE_DEGREE = {"conservative": 3, "nonconservative": 4}
NORMAL_REGULARISATION = 1e-8  # |∇φ| floor relative to 1/ε in n = ∇φ/|∇φ|


def property_map(phi: np.ndarray, liquid: float, gas: float) -> np.ndarray:
    """Eqs 12–13: gas + (liquid − gas)·φ̂ with φ̂ = φ clipped to [0, 1]."""
    return gas + (liquid - gas) * np.clip(phi, 0.0, 1.0)


def mobility(cfg: PhaseFieldConfig, velocity_scale: float, h_min: float) -> float:
    """γ [m/s] = mobility_factor · U, times min(1, h_min/mobility_length) when that length is set.

    With γ fixed, the conservative form smooths the interface along itself (at corners,
    where the normal is ill-defined) with diffusivity ~ γε ∝ h, a rounding of width ~ √(γεT)
    and shape errors of order ½ in h (Zalesak's disk: 0.50 between 160² and 256²); with γ ∝ h
    that diffusivity is O(h²) and the order is ≥ 1 (docs/phase-field.md)."""
    gamma = cfg.mobility_factor * velocity_scale
    if cfg.mobility_length is not None:
        gamma *= min(1.0, h_min / cfg.mobility_length)
    return gamma


def interface_width(h_min: float, width_factor: float) -> float:
    """ε = width_factor · h_min [m]."""
    return width_factor * h_min


def cell_width(msh, eps: float, floor: float) -> fem.Function:
    """ε_K = max(ε, floor · h_K) per cell (DG0) [m], h_K the cell's longest edge.

    Near φ = 1, φ = 1 + ψ, the conservative flux is γ(ε∇ψ + ψ n) with |n| = 1 however small ∇ψ
    is: the sharpening part carries ψ down its own gradient (velocity −γn), so it compresses
    every dip of φ below 1 like a small interface (near φ = 0, every bump above 0), at a rate
    ~γ/h against the diffusion's γε/h². The scheme keeps φ bounded where ε is comparable to the
    cell (Mirjalili, Ivey & Mani 2020, JCP 401, 109006: ε/Δx ≥ (γ/|u| + 1)/(2γ/|u|) for their
    scheme), not in cells many times ε — the coarse cells of a mesh refined around the
    interface, which the floor gives the width they can carry (docs/two-phase.md, sloshing)."""
    V0 = fem.FunctionSpace(msh, ("DG", 0))
    width = fem.Function(V0, name="interface_width")
    h = cell_sizes(msh)
    dofs = V0.dofmap.list.array.reshape(len(h), -1)[:, 0]
    width.x.array[dofs] = np.maximum(eps, floor * h)
    return width


def logistic(d: np.ndarray, eps: float) -> np.ndarray:
    """Equilibrium profile φ(d) = 1/(1+exp(−d/ε)), overflow-safe."""
    return 0.5 * (1.0 + np.tanh(0.5 * d / eps))


def tau_phi(u, dt, h):
    """SUPG parameter of eq 15: [(2/Δt)² + (2|u|/h)²]^(-1/2), written as 1/√(…) of squares
    (the power −½ would compile to a libm ``pow`` per quadrature point, half the assembly time)."""
    return 1.0 / ufl.sqrt((2.0 / dt) ** 2 + 4.0 * ufl.dot(u, u) / h ** 2)


class NodalNormal:
    """n = ∇φ/|∇φ| as a P1 vector field: the cell gradients averaged to the nodes
    (lumped-mass L2 projection), then normalised.

    Cell-wise normals of a P1 field point in noisy directions in the interface tails,
    where the sharpening flux then acts as a random compressive velocity and amplifies
    the noise; the nodal average removes that instability.
    """

    def __init__(self, phi: fem.Function, eps: float):
        msh = phi.function_space.mesh
        self.phi, self.eps = phi, eps
        W = fem.VectorFunctionSpace(msh, ("Lagrange", 1))
        self.n = fem.Function(W, name="normal")
        self.gdim = msh.geometry.dim
        v = ufl.TestFunction(W)
        dx = ufl.dx(metadata={"quadrature_degree": 1})
        self.grad_form = jit.form(ufl.inner(ufl.grad(phi), v) * dx)
        lumped = fem.petsc.assemble_vector(jit.form(ufl.TestFunction(phi.function_space) * dx))
        lumped.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        lumped_fn = fem.Function(phi.function_space)
        lumped_fn.vector.array[:] = lumped.array
        lumped_fn.x.scatter_forward()
        self.lumped = lumped_fn.x.array.copy()
        self.vec = fem.petsc.create_vector(self.grad_form)

    def update(self) -> None:
        with self.vec.localForm() as loc:
            loc.set(0.0)
        assemble_vector(self.vec, self.grad_form)
        self.vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.n.vector.array[:] = self.vec.array
        self.n.x.scatter_forward()
        g = self.n.x.array.reshape(-1, self.gdim) / self.lumped[:, None]
        norm = np.sqrt((g ** 2).sum(axis=1) + (NORMAL_REGULARISATION / self.eps) ** 2)
        self.n.x.array[:] = (g / norm[:, None]).ravel()


def phase_field_residual(phi, w, phi_n, phi_k, normal, u, dt, gamma, eps, form: str, supg: bool, dx, ds,
                         advective=None):
    """Residual F(φ; w) of the Crank–Nicolson scheme, linear in the trial φ; ``eps`` is ε [m], a
    number or a per-cell field (:func:`cell_width`).

    The interface normal is the nodal (P1) normal of the extrapolated φ* = 3/2 φⁿ − 1/2 φⁿ⁻¹
    (second order, fixed during the step; see :class:`NodalNormal`); the remaining polynomial nonlinearity g(φ) = φ(1−φ)
    (or the Allen–Cahn reaction f(φ) = φ(1−φ)(1−2φ)) is linearised by Newton at the
    iterate φ_k, g ≈ g(φ_k) + g'(φ_k)(φ − φ_k), and averaged with its value at φⁿ
    (Crank–Nicolson). Iterating to convergence gives the exact CN solution.

    ``advective`` (DG0, 0 or 1 per cell): where it is 1 the transport is u·∇φ instead of
    ∇·(φu) (the term −χ θ (∇·u) w is added). The coupled model sets it on the cells at and
    inside the blocks, where the advecting field — the fluid's velocity outside, the rigid
    motion inside — is not divergence-free: in divergence form its convergence there
    compresses φ beyond 1 at the block surface.
    """
    theta = 0.5 * (phi + phi_n)
    mesh = w.ufl_function_space().mesh
    n_b = ufl.FacetNormal(mesh)
    outflow = 0.5 * (ufl.dot(u, n_b) + abs(ufl.dot(u, n_b)))
    # advection in divergence form with upwind boundary flux: gas (φ = 0) enters at
    # inflow boundaries, φ leaves with the outflow; ∫φ changes only by that flux.
    F = w * (phi - phi_n) / dt * dx - theta * ufl.dot(u, ufl.grad(w)) * dx \
        + w * theta * outflow * ds \
        + gamma * eps * ufl.dot(ufl.grad(w), ufl.grad(theta)) * dx
    if advective is not None:
        F -= advective * theta * ufl.div(u) * w * dx
    if form == "conservative":
        g_new = phi_k * (1 - phi_k) + (1 - 2 * phi_k) * (phi - phi_k)
        flux = 0.5 * (g_new + phi_n * (1 - phi_n)) * normal
        F -= gamma * ufl.dot(ufl.grad(w), flux) * dx
        source = gamma * ufl.div(flux)          # ∇·(ε∇φ) = 0 inside P1 cells
    else:
        f_new = phi_k * (1 - phi_k) * (1 - 2 * phi_k) + (1 - 6 * phi_k + 6 * phi_k ** 2) * (phi - phi_k)
        reaction = 0.5 * (f_new + phi_n * (1 - phi_n) * (1 - 2 * phi_n)) / eps
        F += gamma * w * reaction * dx
        source = gamma * reaction
    if supg:
        h = ufl.CellDiameter(mesh)
        strong = (phi - phi_n) / dt + ufl.dot(u, ufl.grad(theta)) + source
        F += tau_phi(u, dt, h) * ufl.dot(u, ufl.grad(w)) * strong * dx
    return F


@dataclass
class CellGeometry:
    """P1 dofs and vertex coordinates of the owned cells (for exact cut measures)."""

    dofs: np.ndarray      # (ncells, nv) local dof indices
    coords: np.ndarray    # (ncells, nv, gdim)


def p1_cell_geometry(V: fem.FunctionSpace) -> CellGeometry:
    msh = V.mesh
    tdim = msh.topology.dim
    ncells = msh.topology.index_map(tdim).size_local
    dofs = V.dofmap.list.array.reshape(-1, tdim + 1)[:ncells].copy()
    x = V.tabulate_dof_coordinates()[:, :msh.geometry.dim]
    return CellGeometry(dofs, x[dofs])


def liquid_volume_and_area(geom: CellGeometry, phi_values: np.ndarray, comm: MPI.Comm,
                           area_weights: np.ndarray | None = None) -> tuple[float, float]:
    """Exact |{φ ≥ 1/2}| and |{φ = 1/2}| of the P1 field (collective); with ``area_weights``
    (one per owned cell, e.g. its fluid fraction) each cell's interface measure is weighted."""
    vol, area = cut_measures(geom.coords, phi_values[geom.dofs] - 0.5)
    if area_weights is not None:
        area = area * area_weights
    return comm.allreduce(float(vol.sum()), op=MPI.SUM), comm.allreduce(float(area.sum()), op=MPI.SUM)


def distance_from_profile(phi_values: np.ndarray, eps: float) -> np.ndarray:
    """Invert the equilibrium profile: d = ε ln(φ/(1−φ)) (clipped away from 0 and 1) [m]."""
    p = np.clip(phi_values, 1e-12, 1 - 1e-12)
    return eps * np.log(p / (1 - p))


def shift_interface(phi_values: np.ndarray, shift: float, eps: float) -> np.ndarray:
    """Move the φ = 1/2 surface by ``shift`` [m] along its normal, outward > 0 (eq 17)."""
    shifted = logistic(distance_from_profile(phi_values, eps) + shift, eps)
    # keep values that were outside (0, 1) (over/undershoots) unchanged in sign of error
    return np.where((phi_values > 0) & (phi_values < 1), shifted, phi_values)


def describe_shape(shape: InitialShape) -> str:
    """The set keys of an initial shape, for error messages."""
    keys = {"box": ("lower", "upper", "bed_depth"), "surface_wave": ("depth", "amplitude")}.get(
        shape.shape, ("center", "radius"))
    return ", ".join(f"{k} = {getattr(shape, k)}" for k in keys)


class PhaseField:
    """φ on P1 with its compiled forms and solver; ``advance(dt)`` makes one step."""

    def __init__(self, msh, cfg: PhaseFieldConfig, h_min: float, velocity: fem.Function,
                 velocity_scale: float, dt: float):
        self.cfg = cfg
        self.comm = msh.comm
        self.V = fem.FunctionSpace(msh, ("Lagrange", 1))
        self.phi = fem.Function(self.V, name="phi")
        self.phi_n = fem.Function(self.V, name="phi_n")
        self.phi_k = fem.Function(self.V)
        self.phi_nm1 = fem.Function(self.V, name="phi_nm1")
        self.phi_star = fem.Function(self.V)
        self.u = velocity
        self.eps = interface_width(h_min, cfg.width_factor)
        self.normal = NodalNormal(self.phi_star, self.eps)
        self.gamma_value = mobility(cfg, velocity_scale, h_min)
        self.dt = fem.Constant(msh, PETSc.ScalarType(dt))
        gamma = fem.Constant(msh, PETSc.ScalarType(self.gamma_value))
        dx = ufl.dx(metadata={"quadrature_degree": QUADRATURE_DEGREE[cfg.form]})
        ds = ufl.ds(metadata={"quadrature_degree": 2})
        trial, w = ufl.TrialFunction(self.V), ufl.TestFunction(self.V)
        #: 1 on cells where φ is transported in advective form (see phase_field_residual)
        self.advective_cells = fem.Function(fem.FunctionSpace(msh, ("DG", 0)), name="advective_cells")
        #: ε per cell with ``width_floor`` (:func:`cell_width`), else None: ε everywhere
        self.cell_width = None if cfg.width_floor is None else cell_width(msh, self.eps, cfg.width_floor)
        eps_cells = self.eps if self.cell_width is None else self.cell_width
        F = phase_field_residual(trial, w, self.phi_n, self.phi_k, self.normal.n, self.u, self.dt, gamma,
                                 eps_cells, cfg.form, cfg.supg, dx, ds, self.advective_cells)
        self.a = jit.form(ufl.lhs(F))
        self.L = jit.form(ufl.rhs(F))
        self.mass_form = jit.form(self.phi * ufl.dx(metadata={"quadrature_degree": 2}))
        n_b = ufl.FacetNormal(msh)
        u_out = 0.5 * (ufl.dot(self.u, n_b) + abs(ufl.dot(self.u, n_b)))      # (u·n)⁺
        self.outflow_form = jit.form(0.5 * (self.phi + self.phi_n) * u_out * ds)
        self.outflow_total = 0.0  # ∫∫ φ_θ (u·n)⁺ ds dt: liquid that left through the boundary [m^d]
        self.A = assemble_matrix(self.a)
        self.b = create_vector(self.L)
        self.ksp = make_ksp(self.comm, self.A, "pf_", cfg.petsc)
        self.geometry = p1_cell_geometry(self.V)
        self.steps_done = 0
        self.volume0 = None
        self.mass0 = None
        #: the cut domain whose fluid part holds the liquid (use_cut; None: the whole mesh)
        self.cut = None

    # --- state -------------------------------------------------------------------
    def set_initial(self, shape: InitialShape) -> None:
        self.phi.interpolate(lambda x: logistic(signed_distance(shape, x, self.V.mesh.geometry.dim), self.eps))
        self.phi.x.scatter_forward()
        self.phi_n.x.array[:] = self.phi.x.array
        self.phi_nm1.x.array[:] = self.phi.x.array
        self.volume0 = self.volume()[0]
        self.mass0 = self.mass()
        if not self.volume0 > 0.0:
            raise ConfigError(f"key 'phase_field.initial' ({shape.shape}, {describe_shape(shape)}): the liquid region "
                              "does not overlap the mesh — there is no liquid to simulate (φ = 1 must cover part "
                              "of mesh.lower..mesh.upper)")

    def mass(self) -> float:
        """∫φ dx [m^d] (collective)."""
        return self.comm.allreduce(fem.assemble_scalar(self.mass_form), op=MPI.SUM)

    def volume(self) -> tuple[float, float]:
        """(|{φ ≥ 1/2}|, interface measure) [m^d, m^(d−1)] (collective), of the whole mesh or,
        on a cut domain, of its fluid part: the exact whole-mesh volume minus
        the liquid inside the bodies, the interface measure of each cell times its fluid fraction."""
        weights = None if self.cut is None else self.cut.fluid_fractions()
        vol, area = liquid_volume_and_area(self.geometry, self.phi.x.array, self.comm, weights)
        if self.cut is None:
            return vol, area
        return vol - self.cut.liquid_inside(self.phi), area

    def use_cut(self, cut) -> None:
        """From now on the liquid lives in the fluid part of ``cut`` (anything with
        ``fluid_fractions()`` of the owned cells and ``liquid_inside(phi)`` [m^d], collective):
        :meth:`volume` and the volume correction count only it, and the reference volume is
        the fluid part's now."""
        self.cut = cut
        self.volume0 = self.volume()[0]

    # --- one step ----------------------------------------------------------------
    def advance(self, dt: float) -> int:
        """φⁿ → φⁿ⁺¹ over ``dt`` by Picard iterations from the extrapolated φ* (one linearised solve
        when ``picard_max_iterations`` is 1); returns the number of iterations."""
        self.dt.value = dt
        first = self.steps_done == 0
        self.phi_star.x.array[:] = self.phi_n.x.array if first else \
            1.5 * self.phi_n.x.array - 0.5 * self.phi_nm1.x.array
        self.normal.update()
        self.phi_k.x.array[:] = self.phi_star.x.array
        for it in range(1, self.cfg.picard_max_iterations + 1):     # noqa: B007 (returned)
            self.solve_linearised()
            change = self.comm.allreduce(float(np.abs(self.phi.x.array - self.phi_k.x.array).max(initial=0.0)),
                                         op=MPI.MAX)
            self.phi_k.x.array[:] = self.phi.x.array
            if change <= self.cfg.picard_tolerance:
                break
        linearised = self.cfg.picard_max_iterations == 1
        if not np.isfinite(change) or (change > self.cfg.picard_tolerance and not linearised):
            raise FloatingPointError(f"phase field: Picard iteration did not converge in "
                                     f"{self.cfg.picard_max_iterations} iterations (max change {change:.3g})")
        self.outflow_total += dt * self.comm.allreduce(fem.assemble_scalar(self.outflow_form), op=MPI.SUM)
        if self.cfg.volume_correction:
            self.correct_volume()
        self.phi_nm1.x.array[:] = self.phi_n.x.array
        self.phi_n.x.array[:] = self.phi.x.array
        self.steps_done += 1
        return it

    def solve_linearised(self) -> None:
        """Assemble and solve the system linearised at φ_k."""
        self.A.zeroEntries()
        assemble_matrix(self.A, self.a)
        self.A.assemble()
        with self.b.localForm() as loc:
            loc.set(0.0)
        assemble_vector(self.b, self.L)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        self.ksp.setOperators(self.A)
        solve_ksp(self.ksp, self.b, self.phi.vector)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise FloatingPointError(f"phase-field linear solve failed (KSP reason {reason})")
        self.phi.x.scatter_forward()

    def correct_volume(self) -> float:
        """One shift by L_err = (V − V₀)/A (eqs 16–17); returns L_err [m]."""
        vol, area = self.volume()
        if area <= 0.0:
            return 0.0
        l_err = (vol - self.volume0) / area
        self.phi.x.array[:] = shift_interface(self.phi.x.array, -l_err, self.eps)
        return l_err

    # --- checkpoint --------------------------------------------------------------
    def state(self) -> tuple[dict, dict]:
        """(owned nodal fields as (coords, values), replicated scalars) for a checkpoint."""
        n = self.V.dofmap.index_map.size_local
        x = self.V.tabulate_dof_coordinates()[:n]
        fields = {"phi": (x, self.phi.x.array[:n].copy()), "phi_nm1": (x, self.phi_nm1.x.array[:n].copy())}
        scalars = np.array([self.volume0, self.mass0, float(self.steps_done), self.outflow_total])
        return fields, {"phase_field_scalars": scalars}

    def load_state(self, checkpoint) -> None:
        from ..io.checkpoint import nodal_values_at
        x = self.V.tabulate_dof_coordinates()
        self.phi.x.array[:] = nodal_values_at(x, checkpoint.fields["phi"], "phi")
        self.phi_n.x.array[:] = self.phi.x.array
        self.phi_nm1.x.array[:] = nodal_values_at(x, checkpoint.fields["phi_nm1"], "phi_nm1")
        self.volume0, self.mass0, steps, self.outflow_total = checkpoint.globals["phase_field_scalars"]
        self.steps_done = int(steps)
