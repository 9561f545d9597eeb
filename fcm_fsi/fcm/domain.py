"""The finite-cover fluid domain on a fixed mesh (SPEC §1; issue #5).

The structure's level set s (signed distance, > 0 in the fluid) is held at the mesh
vertices as a P1 field. Its zero set cuts cells; integrals run over the fluid part of each
cut cell only, by moment-fitted weights at the points of the standard rule
(``moments.fitted_weights``), stored in a dolfinx Quadrature space:

    ∫_{Ω_f} f dx  = Σ_K Σ_q ŵ_q |J_K| c_q f(x_q)        (``CutDomain.dx``: f · c_v · dx_q)
    ∫_Γ f dΓ      = Σ_K Σ_q ŵ_q |J_K| d_q f(x_q)        (``surface`` weights d_q)

both exact for polynomials of degree ≤ 2 over the piecewise-planar cut geometry. Only cut
cells need the weights: the cells are tagged (``cell_tags``: uncut fluid, cut, solid) and the
uncut ones are integrated with the plain rule of degree ``plain_degree`` and no weight fields,
solid cells with the plain rule times α. The tags change in place with the cut; forms compiled
as :class:`~fcm_fsi.fluid.tagged_form.TaggedForm` follow them.

Cells inside bodies and vertices with tiny fluid support: the solid part of every cell
carries the fluid equations scaled by α ≪ 1 (a fictitious domain, as in the finite cell
method: volume factor c_v + α(1 − c_v)). Every vertex then has support of relative size
≥ α, so the system stays regular whatever the cut fraction, and the rigid-body motion
that the penalty imposes on Γ is a solution of the fictitious equations inside.

Wall condition (paper eq 5): ∫_Γ p̄ (u − ū)·w dΓ, ū = v + ω × (x − x_c) of the body the
point belongs to, imposed on u^{n+1} (like a Dirichlet condition; on u^{n+θ} Crank–Nicolson
would let the wall velocity oscillate). Penalty scaling

    p̄ = γ (μ/h + ρ h/Δt)          [Pa s/m]

i.e. γ times the larger of the viscous and inertial stiffness of a cell of size h, so the
wall slip velocity is ≈ 1/γ of the velocity scale at any Reynolds number.
In a two-phase flow ρ and μ here are the cell-wise means ρ̄_K, μ̄_K (constant per cell, so the
penalty matrix is integrated exactly and stays positive semi-definite: ``penalty_coefficient``).

Cut-cell extension (β = ``extension`` > 0; the coupled runs' default β = 1): the solid part
of every *cut* cell (weight 1 − c_v at its points) also carries a Brinkman term
∫ β ρ/Δt (u − ū)·w and β times the PSPG term ∫ τ ∇q/ρ̄ · R_M. A node whose support is
almost all solid is then held at ū by a mass-like term instead of by the α-scaled equations,
and the pressure is extended into the body by a full-strength pressure Laplacian instead of
an α-weak one, so the wall pressure trace of a sliver cell stays bounded. The perturbation
is confined to the solid side of Γ, where u = ū holds anyway up to the wall slip. The
Brinkman term's reaction is added to the body load below, so the exchange stays exact.

Force on body b: the traction the penalty exerts, F_b = ∫_{Γ_b} p̄ (u − ū) dΓ, and the
torque about its centre T_b = ∫_{Γ_b} (x − x_b) × p̄ (u − ū) dΓ. Since the penalty term
is the only coupling between wall and fluid in the discrete equations, this equals the
variational reaction of the fluid residual tested with the constant unit vectors on the
cut cells, and it is what the DEM receives (so momentum is exchanged exactly).
"""
from __future__ import annotations

from dataclasses import dataclass

import basix
import dolfinx.mesh
import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from ..fluid.navier_stokes import cell_size, momentum_residual
from ..fluid.tagged_form import TaggedForm
from .moments import fitted_weights

#: wall conditions on Γ (module docstring): the paper's penalty; penalty + the pressure part of
#: the wall traction (consistent for a fluid at rest: no leak under hydrostatic pressure, and
#: stable for any cut since the added pressure terms are skew); full symmetric Nitsche
WALL_TERMS = ("penalty", "pressure", "nitsche")

#: quadrature degree of all fluid forms on a cut mesh: the smallest standard rule with at
#: least as many points as monomials of degree ≤ 2 (2D: 7 points ≥ 6; 3D: 14 points ≥ 10)
CUT_QUADRATURE_DEGREE = {2: 5, 3: 4}

#: cell classes of the cut (``CutDomain.cell_tags`` values): every vertex in the fluid, cut by Γ,
#: every vertex in a body
FLUID_CELL, CUT_CELL, SOLID_CELL = 0, 1, 2


def cut_cells(values: np.ndarray) -> np.ndarray:
    """Cells (rows of vertex level-set values) that Γ cuts: some vertex in the body, some not."""
    return (values.min(axis=1) < 0) & (values.max(axis=1) >= 0)


def cell_classes(values: np.ndarray) -> np.ndarray:
    """FLUID_CELL, CUT_CELL or SOLID_CELL per row of vertex level-set values (fluid where ≥ 0)."""
    classes = np.full(len(values), CUT_CELL, np.int32)
    classes[values.min(axis=1) >= 0] = FLUID_CELL
    classes[values.max(axis=1) < 0] = SOLID_CELL
    return classes


class WeightedMeasure:
    """``f * WeightedMeasure(dx, c)`` is ``f * c * dx``: a measure with a weight field."""

    def __init__(self, dx: ufl.Measure, weight) -> None:
        self.dx, self.weight = dx, weight

    def __rmul__(self, integrand):
        return (integrand * self.weight) * self.dx


class FluidMeasure:
    """``f * FluidMeasure`` = ∫ f over the fluid with the fictitious α inside bodies: the plain
    rule on uncut fluid cells, α × the plain rule on solid cells, the fitted volume weights
    (c_v(1 − α) + α at the points) on cut cells."""

    def __init__(self, plain: ufl.Measure, fitted: ufl.Measure, weight, alpha: float) -> None:
        self.plain, self.fitted, self.weight, self.alpha = plain, fitted, weight, alpha

    def __rmul__(self, integrand):
        return (integrand * self.plain(FLUID_CELL) + (self.alpha * integrand) * self.plain(SOLID_CELL)
                + (integrand * self.weight) * self.fitted(CUT_CELL))


@dataclass
class CutStatistics:
    """Global counts of the current cut (rank-summed)."""

    cut_cells: int
    solid_cells: int
    fluid_volume: float        # exact measure of the fluid part (m³; m² in 2D)
    surface: float             # exact measure of the cut surface (m²; m in 2D)
    min_cut_fraction: float    # smallest fluid fraction of a cut cell


class CutDomain:
    """Quadrature weights, wall velocity and body forces of the cut fluid domain.

    mesh: dolfinx mesh (P1 simplices); alpha: fictitious-domain factor of the solid part;
    penalty: γ of the penalty scaling (module docstring); extension: β of the cut-cell
    extension (module docstring), 0 = off; plain_degree: quadrature degree on uncut cells
    (default the cut rule's degree).

    Forms over :attr:`dx`, :attr:`dGamma` and :attr:`dExt` depend on :attr:`cell_tags`;
    compile them as :class:`~fcm_fsi.fluid.tagged_form.TaggedForm` so they follow the cut.
    """

    def __init__(self, mesh, alpha: float = 1e-3, penalty: float = 100.0, wall: str = "pressure",
                 extension: float = 0.0, slip: bool = False, plain_degree: int | None = None) -> None:
        if wall not in WALL_TERMS:
            raise ValueError(f"wall = {wall!r}; allowed: {', '.join(WALL_TERMS)}")
        self.mesh, self.comm, self.wall = mesh, mesh.comm, wall
        self.slip = bool(slip)
        if self.slip and wall == "nitsche":
            raise ValueError("a slip wall takes wall = 'penalty' or 'pressure' (the Nitsche terms are no-slip)")
        self.alpha, self.gamma = float(alpha), float(penalty)
        tdim = mesh.topology.dim
        self.gdim = mesh.geometry.dim
        self.degree = CUT_QUADRATURE_DEGREE[tdim]
        cell = mesh.ufl_cell()
        ct = basix.CellType.triangle if tdim == 2 else basix.CellType.tetrahedron
        self.ref_points, self.ref_weights = basix.make_quadrature(ct, self.degree)
        qe = ufl.FiniteElement("Quadrature", cell, self.degree, quad_scheme="default")
        self.Vq = fem.FunctionSpace(mesh, qe)
        self.volume_weight = fem.Function(self.Vq, name="fluid_weight")
        self.surface_weight = fem.Function(self.Vq, name="surface_weight")
        self.extension_weight = fem.Function(self.Vq, name="extension_weight")
        self.extension = float(extension)
        imap = mesh.topology.index_map(tdim)
        self.n_owned = imap.size_local
        # every owned cell tagged; until the first update all count as cut (weights everywhere)
        self.cell_tags = dolfinx.mesh.meshtags(mesh, tdim, np.arange(self.n_owned, dtype=np.int32),
                                               np.full(self.n_owned, CUT_CELL, np.int32))
        self.plain_degree = self.degree if plain_degree is None else int(plain_degree)
        self.dx_q = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": self.degree})
        fitted = ufl.Measure("dx", domain=mesh, subdomain_data=self.cell_tags,
                             metadata={"quadrature_degree": self.degree})
        plain = ufl.Measure("dx", domain=mesh, subdomain_data=self.cell_tags,
                            metadata={"quadrature_degree": self.plain_degree})
        self.dx = FluidMeasure(plain, fitted, self.volume_weight, self.alpha)
        self.dGamma = WeightedMeasure(fitted(CUT_CELL), self.surface_weight)
        self.dExt = WeightedMeasure(fitted(CUT_CELL), self.extension_weight)   # solid part of cut cells

        ncells = imap.size_local + imap.num_ghosts
        nv = tdim + 1
        self.geom_cells = mesh.geometry.dofmap.array.reshape(ncells, -1)[:, :nv]
        self.cell_coords = np.ascontiguousarray(mesh.geometry.x[self.geom_cells][:, :, : self.gdim])
        own = self.cell_coords[: self.n_owned]
        self.owned_cell_volume = np.abs(np.linalg.det(own[:, 1:] - own[:, :1])) / (2.0 if self.gdim == 2 else 6.0)
        self.q_dofs = self.Vq.dofmap.list.array.reshape(ncells, -1)
        self.V1 = fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
        self.S1 = fem.FunctionSpace(mesh, ("Lagrange", 1))
        self.wall_velocity = fem.Function(self.V1, name="wall_velocity")
        self.level_set = fem.Function(self.S1, name="structure_level_set")
        self.level_dofs = self.node_map(self.S1)
        self.wall_dofs = self.node_map(self.V1)
        self.cell_owner = np.full(ncells, -2, np.int64)
        self.cell_second, self.cell_share = np.full(ncells, -2, np.int64), np.zeros(ncells)
        self.body_cells = np.zeros(ncells, bool)
        self.fluid_measure = np.zeros(ncells)
        self.surface_measure = np.zeros(ncells)
        self.h = cell_size(mesh)
        self._force_forms = None

    @property
    def fluid_fraction(self):
        """c_v at the quadrature points (1 fluid, 0 solid) as a UFL expression: the volume
        weight without the fictitious α."""
        return (self.volume_weight - self.alpha) / (1 - self.alpha)

    # ----------------------------------------------------------------- update
    def node_map(self, V: fem.FunctionSpace) -> np.ndarray:
        """Block dof of the P1 space ``V`` at each mesh vertex (:attr:`nodes` order): a P1
        space numbers the vertices of every cell in the geometry's local order."""
        cells = V.dofmap.list.array.reshape(self.geom_cells.shape[0], -1)
        out = np.empty(self.mesh.geometry.x.shape[0], np.int64)
        out[self.geom_cells.ravel()] = cells.ravel()
        return out

    @property
    def nodes(self) -> np.ndarray:
        """Mesh vertex coordinates (n, 3) [m] where the level set is given (this rank, incl. ghosts)."""
        return self.mesh.geometry.x

    def update(self, level: np.ndarray, owner: np.ndarray, wall_velocity: np.ndarray,
               share: tuple[np.ndarray, np.ndarray] | None = None) -> CutStatistics:
        """New cut from the level set at :attr:`nodes` (> 0 fluid), the owning body of each
        node (int, < 0 for none/static) and the wall velocity ū at each node (n, gdim).
        ``share`` = (second body, its weight in [0, ½]) at each node: a cell's load then goes
        to the two bodies of its deepest vertex in those proportions (default: all to the
        owner). Local work only, except the statistics (one allreduce)."""
        values = np.ascontiguousarray(level[self.geom_cells])
        cv, cs, self.fluid_measure, self.surface_measure = fitted_weights(
            self.cell_coords, values, self.ref_points, self.ref_weights)
        a = self.alpha
        self.volume_weight.x.array[self.q_dofs] = (1 - a) * cv + a
        self.surface_weight.x.array[self.q_dofs] = cs
        classes = cell_classes(values)
        self.extension_weight.x.array[self.q_dofs] = np.where((classes == CUT_CELL)[:, None], 1.0 - cv, 0.0)
        self.cell_tags.values[:] = classes[: self.n_owned]
        self.level_set.x.array[self.level_dofs] = level
        self.set_wall_velocity(wall_velocity)
        # a cell belongs to the body owning its deepest vertex
        deepest = np.argmin(values, axis=1)
        rows = np.arange(len(values))
        self.cell_owner = owner[self.geom_cells[rows, deepest]]
        if share is None:
            self.cell_second, self.cell_share = np.full_like(self.cell_owner, -2), np.zeros(len(rows))
        else:
            self.cell_second = share[0][self.geom_cells[rows, deepest]]
            self.cell_share = np.where((self.cell_second >= 0) & (self.cell_owner >= 0),
                                       share[1][self.geom_cells[rows, deepest]], 0.0)
        self.body_cells = values[rows, deepest] <= 0     # cells at (cut or touching Γ) or inside a body
        return self.statistics(values)

    def set_wall_velocity(self, wall_velocity: np.ndarray) -> None:
        """The wall velocity ū (n, gdim) at each node of :attr:`nodes`, the cut unchanged."""
        bs = self.V1.dofmap.index_map_bs
        for d in range(self.gdim):
            self.wall_velocity.x.array[bs * self.wall_dofs + d] = wall_velocity[:, d]

    def fluid_fractions(self) -> np.ndarray:
        """Fluid fraction |K ∩ Ω_f| / |K| of every owned cell (0 solid … 1 fluid)."""
        return np.clip(self.fluid_measure[: self.n_owned] / self.owned_cell_volume, 0.0, 1.0)

    def statistics(self, values: np.ndarray) -> CutStatistics:
        own = slice(0, self.n_owned)
        v = values[own]
        cut = cut_cells(v)
        solid = v.max(axis=1) < 0
        frac = self.fluid_measure[own][cut] / self.owned_cell_volume[cut]
        s = self.comm.allreduce
        return CutStatistics(cut_cells=s(int(cut.sum())), solid_cells=s(int(solid.sum())),
                             fluid_volume=s(float(self.fluid_measure[own].sum())),
                             surface=s(float(self.surface_measure[own].sum())),
                             min_cut_fraction=self.comm.allreduce(float(frac.min(initial=1.0)), op=MPI.MIN))

    # ------------------------------------------------------------------ forms
    def penalty_coefficient(self, parts, h):
        """p̄ = γ (μ/h + ρ h/Δt) [Pa s/m] (module docstring), with the cell-wise ρ̄, μ̄ of a
        two-phase flow (``parts.rho_pspg``, ``parts.mu_cell``) where given.

        Why cell-wise: the surface weights integrate polynomials of degree ≤ 2 exactly, so the
        penalty matrix ∫_Γ p̄ φ_i φ_j dΓ is exact — positive semi-definite — only if p̄ is
        constant per cell. With the P1 ρ(φ) it is cubic; where Γ runs within a few hundredths
        of h of a row of mesh nodes the fitted weights are large and of both signs, the matrix
        loses definiteness by γ ρ h/Δt × the density's variation over the cell, and a box whose
        face came to rest there in air blew up within 0.01 s (docs/design-notes.md)."""
        return self.gamma * (parts.cell_viscosity / h + parts.cell_density * h / parts.dt)

    def wall_normal(self):
        """Unit normal of Γ pointing out of the fluid (into the body): −∇s/|∇s|, cell-wise."""
        g = ufl.grad(self.level_set)
        return -g / ufl.sqrt(ufl.inner(g, g) + 1e-300)

    def wall_traction(self, parts):
        """Traction the wall exerts on the fluid per unit area, t_w, so that the body feels −t_w:
        penalty: −p̄(u − ū); pressure: −(1 − α) p n − p̄(u − ū); nitsche: (1 − α) σ(u_θ, p)n − p̄(u − ū).

        Why (1 − α): the Galerkin terms integrated by parts leave −∫_Γ σn·w from the fluid side
        (weight 1) and +α ∫_Γ σn·w from the fictitious side (weight α), i.e. −(1 − α) ∫_Γ σn·w;
        the consistency term must cancel exactly that, or a fluid at rest under gravity is not
        a discrete solution (a leak of order α p/p̄ through Γ, and a buoyancy off by α).
        """
        t = -self._pbar * self.constrained(parts.u - self.wall_velocity)
        keep = 1.0 - self.alpha
        if self.wall != "penalty":
            t = t - keep * parts.p * self.wall_normal()
        if self.wall == "nitsche":
            t = t + keep * 2 * parts.mu * ufl.dot(ufl.sym(ufl.grad(parts.u_theta)), self.wall_normal())
        return t

    def extension_traction(self, parts):
        """Force per unit volume the extension's Brinkman term exerts on the body, β ρ/Δt (u − ū),
        on the solid part of cut cells (measure :attr:`dExt`)."""
        # the cell-wise density, as in p̄
        return self.extension * parts.cell_density / parts.dt * self.constrained(parts.u - self.wall_velocity)

    def constrained(self, slip_velocity):
        """The part of u − ū the wall penalises: all of it (no-slip), or with ``slip`` only its
        normal component ((u − ū)·n) n, so the wall exerts no shear.

        Why slip: on cells much larger than the boundary layer a no-slip wall is not resolved;
        its discrete reaction is the momentum of the near-wall cells stopped every step, a
        shear of order ρ h |u|/Δt (≈ 8e5 Pa at h = 0.8 m, 10 m/s, Δt = 0.01 s), against
        ρ u² C_f ≈ 3e2 Pa of a real wall — at the tsunami's coarse level it lifted the front
        wall with meganewtons as the water ran up it (docs/design-notes.md)."""
        if not self.slip:
            return slip_velocity
        n = self.wall_normal()
        return ufl.dot(slip_velocity, n) * n

    def penalty_term(self):
        """The NS extra term of the wall (pass as ``extra_terms=[...]``): −∫_Γ t_w·w dΓ with
        t_w of :meth:`wall_traction`, plus the adjoint terms that keep the pressure coupling
        skew (``pressure``: −∫_Γ q n·(u − ū) dΓ) or make the viscous part symmetric
        (``nitsche``: −∫_Γ (2μ ε(w)n + q n)·(u − ū) dΓ)."""
        def term(parts):
            self._pbar = self.penalty_coefficient(parts, self.h)
            self._parts = parts
            F = -ufl.inner(self.wall_traction(parts), parts.w) * self.dGamma
            if self.extension > 0:
                F = F + ufl.inner(self.extension_traction(parts), parts.w) * self.dExt
                F = F + self.extension * parts.tau_supg * ufl.inner(ufl.grad(parts.q) / parts.cell_density,
                                                                    momentum_residual(parts)) * self.dExt
            if self.wall != "penalty":
                adj = parts.q * self.wall_normal()
                if self.wall == "nitsche":
                    adj = adj + 2 * parts.mu * ufl.dot(ufl.sym(ufl.grad(parts.w)), self.wall_normal())
                F = F - (1.0 - self.alpha) * ufl.inner(adj, parts.u - self.wall_velocity) * self.dGamma
            return F
        return term

    def _build_force_forms(self):
        """Cell-wise traction integrals: F_K = ∫_{Γ∩K} t dΓ and the moment ∫ x × t dΓ,
        t = p̄ (u − ū), as DG0 vectors (assembled, not summed, so bodies can be split)."""
        t = -self.wall_traction(self._parts)
        # the extension's Brinkman term acts on the solid part of cut cells: its reaction is load too
        loads = [(t, self.dGamma)]
        if self.extension > 0:
            loads.append((self.extension_traction(self._parts), self.dExt))
        self._force_forms = self._cellwise_load_forms(loads)

    def _cellwise_load_forms(self, loads):
        """Compiled DG0 force and moment forms Σ ∫ f · v₀ dm and Σ ∫ (x × f) v₀ dm over the
        (force density, measure) pairs ``loads``, with their dof lists, for :meth:`_assembled_loads`."""
        x = ufl.SpatialCoordinate(self.mesh)
        V0 = fem.VectorFunctionSpace(self.mesh, ("DG", 0))
        v0 = ufl.TestFunction(V0)
        force = TaggedForm(sum(ufl.inner(f, v0) * m for f, m in loads))
        if self.gdim == 2:
            S0 = fem.FunctionSpace(self.mesh, ("DG", 0))
            moment = TaggedForm(sum((x[0] * f[1] - x[1] * f[0]) * ufl.TestFunction(S0) * m for f, m in loads))
            dofs_m = S0.dofmap.list.array
        else:
            moment = TaggedForm(sum(ufl.inner(ufl.cross(x, f), v0) * m for f, m in loads))
            dofs_m = V0.dofmap.list.array
        return force, moment, V0.dofmap.list.array, dofs_m

    def body_forces(self, nbodies: int, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fluid force (nbodies, gdim) [N; N/m in 2D] and torque about ``centres`` (nbodies, 3)
        [N m] on each body from the NS state the wall term was built with. Collective; same on all ranks."""
        if self._force_forms is None:
            self._build_force_forms()
        return self._assembled_loads(self._force_forms, nbodies, centres)

    def pressure_load(self, nbodies: int, centres: np.ndarray, pressure, weight) -> tuple[np.ndarray, np.ndarray]:
        """−∫_Γ w p n dΓ per body [N; N/m in 2D] and its torque about ``centres`` [N m], n the
        structure's outward normal (−:meth:`wall_normal`), cells split over the bodies as in
        :meth:`body_forces`; ``pressure`` and ``weight`` UFL expressions (forms compiled once per
        pair). Collective."""
        key = (id(pressure), id(weight))
        if getattr(self, "_pressure_key", None) != key:
            # −w p n out of the structure = w p × the wall normal (out of the fluid)
            self._pressure_forms = self._cellwise_load_forms([(weight * pressure * self.wall_normal(), self.dGamma)])
            self._pressure_key, self._pressure_refs = key, (pressure, weight)   # the refs keep id() unique
        return self._assembled_loads(self._pressure_forms, nbodies, centres)

    def _assembled_loads(self, forms, nbodies: int, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-body force and torque of cell-wise (DG0) force and moment forms."""
        fF, fM, dofs_f, dofs_m = forms
        own = self.n_owned
        vf = fem.petsc.assemble_vector(fF.form)      # no ghost accumulation: DG0 dofs are cell-local
        vm = fem.petsc.assemble_vector(fM.form)
        nm = 1 if self.gdim == 2 else 3
        force = self._to_bodies(vf.array.reshape(-1, self.gdim)[dofs_f[:own]], nbodies)
        moment = self._to_bodies(vm.array.reshape(-1, nm)[dofs_m[:own]], nbodies)
        vf.destroy(), vm.destroy()
        return self._force_and_torque(force, moment, nbodies, centres)

    def _force_and_torque(self, force: np.ndarray, moment: np.ndarray, nbodies: int,
                          centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Summed over the ranks; the moment about the origin moved to ``centres``."""
        force = self.comm.allreduce(force, op=MPI.SUM)
        moment = self.comm.allreduce(moment, op=MPI.SUM)
        c = np.asarray(centres, dtype=float).reshape(nbodies, -1)
        torque = np.zeros((nbodies, 3))
        if self.gdim == 2:
            torque[:, 2] = moment[:, 0] - (c[:, 0] * force[:, 1] - c[:, 1] * force[:, 0])
        else:
            torque[:] = moment - np.cross(c[:, :3], force)
        return force, torque

    def _to_bodies(self, cellwise: np.ndarray, nbodies: int) -> np.ndarray:
        """Sum owned-cell values (n_owned, k) per body (nbodies, k) by the cell ownership of
        :meth:`update` (owner, and the shared part to the second body); cells of no body or
        of static shapes count for none. Local."""
        own = self.n_owned
        owner, second, w = self.cell_owner[:own], self.cell_second[:own], self.cell_share[:own]
        out = np.zeros((nbodies,) + cellwise.shape[1:])
        mask = owner >= 0
        np.add.at(out, owner[mask], cellwise[mask] * (1.0 - w[mask]).reshape((-1,) + (1,) * (cellwise.ndim - 1)))
        shared = mask & (w > 0)
        np.add.at(out, second[shared], cellwise[shared] * w[shared].reshape((-1,) + (1,) * (cellwise.ndim - 1)))
        return out

    def wetted_mean(self, nbodies: int, value) -> np.ndarray:
        """Mean of a scalar field over each body's cut surface, (nbodies,); NaN for a body
        with no cut surface. Collective; same on all ranks."""
        # forms compiled once per field (the reference kept here also keeps id() unique)
        if getattr(self, "_wetted_value", None) is not value:
            S0 = fem.FunctionSpace(self.mesh, ("DG", 0))
            v0 = ufl.TestFunction(S0)
            self._wetted_forms = (TaggedForm(value * v0 * self.dGamma), TaggedForm(v0 * self.dGamma),
                                  S0.dofmap.list.array)
            self._wetted_value = value
        f_val, f_area, dofs = self._wetted_forms
        own = self.n_owned
        sums = np.zeros((2, nbodies))
        for k, form in enumerate((f_val, f_area)):
            vec = fem.petsc.assemble_vector(form.form)
            sums[k] = self._to_bodies(vec.array[dofs[:own]], nbodies)
            vec.destroy()
        sums = self.comm.allreduce(sums, op=MPI.SUM)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(sums[1] > 0, sums[0] / np.where(sums[1] > 0, sums[1], 1.0), np.nan)

    def fluid_volume(self) -> float:
        """∫ 1 over the fluid part by the fitted weights (equals the exact cut measure)."""
        vol = fem.assemble_scalar(fem.form(self.fluid_fraction * self.dx_q))
        return float(self.comm.allreduce(vol, op=MPI.SUM))

    def surface_area(self) -> float:
        """∫_Γ 1 by the fitted surface weights (equals the exact cut-surface measure)."""
        val = fem.assemble_scalar(fem.form(self.surface_weight * self.dx_q))
        return float(self.comm.allreduce(val, op=MPI.SUM))
