"""The cut fluid domain with its wall terms: what the fluid imposes on the structure surface Γ
of :class:`fcm_fsi.fcm.domain.CutGeometry` (SPEC §1; issue #5), and the loads it exerts on the
bodies.

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

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from .. import jit
from ..fcm.domain import CutGeometry, CutStatistics
from .ns_forms import cell_size, momentum_residual
from .tagged_form import TaggedForm

#: wall conditions on Γ (module docstring): the paper's penalty; penalty + the pressure part of
#: the wall traction (consistent for a fluid at rest: no leak under hydrostatic pressure, and
#: stable for any cut since the added pressure terms are skew); full symmetric Nitsche
WALL_TERMS = ("penalty", "pressure", "nitsche")


class CutDomain(CutGeometry):
    """The cut geometry with the wall velocity, the wall terms and the body forces.

    mesh: dolfinx mesh (P1 simplices); alpha: fictitious-domain factor of the solid part;
    penalty: γ of the penalty scaling (module docstring); extension: β of the cut-cell
    extension (module docstring), 0 = off; slip: the wall penalises only the normal velocity;
    plain_degree: quadrature degree on uncut cells (default the cut rule's degree).

    Forms over :attr:`dx`, :attr:`dGamma` and :attr:`dExt` depend on :attr:`cell_tags`;
    compile them as :class:`~fcm_fsi.fluid.tagged_form.TaggedForm` so they follow the cut.
    """

    def __init__(self, mesh, alpha: float = 1e-3, penalty: float = 100.0, wall: str = "pressure",
                 extension: float = 0.0, slip: bool = False, plain_degree: int | None = None) -> None:
        if wall not in WALL_TERMS:
            raise ValueError(f"wall = {wall!r}; allowed: {', '.join(WALL_TERMS)}")
        self.wall = wall
        self.slip = bool(slip)
        if self.slip and wall == "nitsche":
            raise ValueError("a slip wall takes wall = 'penalty' or 'pressure' (the Nitsche terms are no-slip)")
        super().__init__(mesh, alpha, plain_degree)
        self.gamma = float(penalty)
        self.extension = float(extension)
        self.V1 = fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
        self.wall_velocity = fem.Function(self.V1, name="wall_velocity")
        self.wall_dofs = self.node_map(self.V1)
        self.h = cell_size(mesh)
        self._force_forms = None
        # the bodies at the mesh vertices as the last update left them: fluid side (level set > 0)
        # the wall velocity ū and the velocity the phase field moves with inside them (rigid_inside)
        # [m/s] (n, gdim)
        self.node_fluid = np.ones(self.nodes.shape[0], bool)
        self.node_wall_velocity = np.zeros((self.nodes.shape[0], self.gdim))
        self.node_inside_velocity = self.node_wall_velocity
        self._node_maps = {}            # id(function space) → (space, its node at each vertex)
        self._density_forms = None      # fluid_part_density: (rho, its forms)
        self._inside_form = None        # liquid_inside: (phi, its form)

    def update(self, level: np.ndarray, owner: np.ndarray, wall_velocity: np.ndarray,
               share: tuple[np.ndarray, np.ndarray] | None = None,
               inside_velocity: np.ndarray | None = None) -> CutStatistics:
        """New cut (:meth:`CutGeometry.update`: level set, owning body and ``share`` at each
        node) and the wall velocity ū at each node (n, gdim), ``inside_velocity`` as in
        :meth:`set_wall_velocity`. Returns the cut's statistics."""
        stats = super().update(level, owner, share)
        self.node_fluid = level > 0
        self.set_wall_velocity(wall_velocity, inside_velocity)
        return stats

    def set_wall_velocity(self, wall_velocity: np.ndarray, inside_velocity: np.ndarray | None = None) -> None:
        """The wall velocity ū (n, gdim) at each node of :attr:`nodes`, the cut unchanged; and
        the velocity the phase field moves with inside the bodies (:meth:`rigid_inside`):
        ``inside_velocity`` (n, gdim), or ū itself when None."""
        bs = self.V1.dofmap.index_map_bs
        for d in range(self.gdim):
            self.wall_velocity.x.array[bs * self.wall_dofs + d] = wall_velocity[:, d]
        self.node_wall_velocity = wall_velocity
        self.node_inside_velocity = wall_velocity if inside_velocity is None else inside_velocity

    # ------------------------------------------------ the bodies as the phase field sees them
    def _vertex_nodes(self, V: fem.FunctionSpace) -> np.ndarray:
        """:meth:`node_map` of ``V``, computed once per space."""
        key = id(V)
        if key not in self._node_maps:
            self._node_maps[key] = (V, self.node_map(V))     # the space kept so its id stays unique
        return self._node_maps[key][1]

    def fluid_nodes(self, V: fem.FunctionSpace) -> np.ndarray:
        """True at the nodes of the P1 vector space ``V`` on the fluid side (level set > 0; this
        rank incl. ghosts): the fictitious flow inside the bodies limits neither the CFL step
        nor the reported speed."""
        nodes = self._vertex_nodes(V)
        out = np.ones(V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts, bool)
        out[nodes] = self.node_fluid
        return out

    def rigid_inside(self, u_values: np.ndarray, V: fem.FunctionSpace) -> None:
        """The phase field inside the bodies moves with them: set ``u_values`` (the array of a
        P1 vector function on ``V``) to the bodies' velocity (:meth:`set_wall_velocity`) at the
        nodes inside (level set ≤ 0), in place."""
        nodes = self._vertex_nodes(V)
        u = u_values.reshape(-1, self.gdim)
        rigid = np.zeros_like(u)
        rigid[nodes] = self.node_inside_velocity
        inside = ~self.fluid_nodes(V)
        u[inside] = rigid[inside]

    def fluid_part_density(self, rho, rho_cell: fem.Function, lo: float, hi: float) -> None:
        """``rho_cell`` [kg/m³] := the mean of ``rho`` over each cell's weighted fluid part, not
        its midpoint: a cut cell whose fluid part is air must not take the water carried in its
        fictitious part, nor the reverse. Clipped to [lo, hi] (the phases' densities): the
        fitted weights may be negative at some points, and the mean sets the wall penalty p̄
        and the PSPG scaling, which must stay positive."""
        if self._density_forms is None or self._density_forms[0] is not rho:
            v0 = ufl.TestFunction(rho_cell.function_space)
            self._density_forms = (rho, TaggedForm(rho * v0 * self.dx), TaggedForm(v0 * self.dx))
        num = fem.petsc.assemble_vector(self._density_forms[1].form)
        den = fem.petsc.assemble_vector(self._density_forms[2].form)
        rho_cell.x.array[: len(num.array)] = np.clip(num.array / den.array, lo, hi)
        rho_cell.x.scatter_forward()
        num.destroy(), den.destroy()

    def liquid_inside(self, phi: fem.Function) -> float:
        """|{φ ≥ ½}| inside the bodies [m^d]: the indicator at the cut quadrature points weighted
        by the solid fraction (collective)."""
        if self._inside_form is None or self._inside_form[0] is not phi:
            liquid = ufl.conditional(ufl.ge(phi, 0.5), 1.0, 0.0)
            self._inside_form = (phi, jit.form(liquid * (1 - self.fluid_fraction) * self.dx_q))
        return self.comm.allreduce(fem.assemble_scalar(self._inside_form[1]), op=MPI.SUM)

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
