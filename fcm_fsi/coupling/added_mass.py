"""Added-mass tensors of the moving bodies in the cut fluid, from the pressure impulse of
inviscid incompressible flow at the current geometry (``coupling.added_mass_model: potential``).

Why: the explicit coupling is stable only while the added-mass stabilisation m̃ follows the
fluid's real added mass m_a (module docstring of ``simulation.coupled``). A fixed C_a ρ V_b
cannot: a piece of debris approaching the floor or a neighbour drives the water out of the
closing gap, and its added mass grows like ρL³/(12 g) per unit depth as the gap g closes
(docs/design-notes.md). This module computes m_a of each moving body, or of each
bonded cluster, on the same mesh, cut and density field as the fluid, every fluid step.

The problem (pressure impulse of a unit rigid acceleration; Batchelor §6.4): for a mode
m(x) of body b — a translation e_k or a rotation e_k × (x − X_b) — find p ∈ P1 with

    ∫_Ωf (1/ρ) ∇p·∇q dx = −∫_Γb (m·n) q dΓ        for all q,   p = 0 on open boundaries,

n the unit normal of Γ out of the fluid (``CutDomain.wall_normal``), Ωf the fluid part with
the fictitious α-scaled solid part (``CutDomain.dx``), rigid walls, the floor and the other
bodies Neumann (they stand still while b accelerates). The load of that pressure on body c
in mode j is ∫_Γc p (m_j·n) dΓ = −M_{cj,bk}, so

    M = Bᵀ A⁻¹ B,   B = [b_{b,k}] the right-hand sides,

symmetric positive semi-definite by construction. ρ is the two-phase density field, so air
(ρ_air ≪ ρ_water) carries almost no impulse and p ≈ 0 at the free surface, as it should.

B is assembled cheaply for any grouping of the cells: the mixed matrices
C_f = ∫_Γ f q v₀ dΓ (v₀ ∈ DG0, q ∈ P1) for f = n_j and (x × n)_k are assembled once per step,
and b = C_fᵀ χ for the DG0 indicator χ of a body's (or cluster's) cells, with the rotation
about X as (x × n) − X × n. Cost per step: one P1 Laplacian, its factorisation, and gdim(+rot)
solves per moving body or cluster.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from .. import jit
from ..fluid.solvers import DIRECT_LU, make_ksp
from ..fluid.solvers import solve as solve_ksp
from ..fluid.tagged_form import TaggedForm
from ..mesh.build import mesh_extent
from .dem_side import block_volume

#: solver of the pressure-impulse Laplacian (a symmetric positive definite P1 system); M = Bᵀ A⁻¹ B is
#: a quadratic form, so its error is of the order of the squared solve error: on the tsunami's debris the
#: largest eigenvalues at rtol 1e-6 agree with those at 1e-8 to 2e-8, in 5 BoomerAMG iterations instead of 7
POISSON_2D = dict(DIRECT_LU)
POISSON_3D = {"ksp_type": "cg", "ksp_rtol": 1e-6, "ksp_max_it": 2000, "pc_type": "hypre",
              "pc_hypre_type": "boomeramg"}
#: 3D Laplacians with at most this many unknowns are factorised (POISSON_2D's LU) instead: a
#: step's factorisation and its 6 solves per moving group cost less than BoomerAMG's set-up and
#: CG there
POISSON_3D_DIRECT_LIMIT = 50_000


def rigid_modes(gdim: int) -> int:
    """Number of rigid-body modes of a body: 3 in 2D (x, y, rotation about z), 6 in 3D."""
    return 3 if gdim == 2 else 6


class PotentialAddedMass:
    """Added-mass tensors (modes × modes) of groups of cells of a :class:`CutDomain`.

    cut: the cut domain (its level set, weights and cell ownership as last updated);
    density: the fluid density ρ (a UFL expression or Function; two-phase: the P1 ρ(φ));
    open_facets: local indices of the owned boundary facets where p = 0 (do-nothing
    boundaries); none → p is pinned at one node (a closed container)."""

    def __init__(self, cut, density, open_facets: np.ndarray | None = None) -> None:
        self.cut = cut
        mesh = cut.mesh
        self.comm = mesh.comm
        self.gdim = gdim = mesh.geometry.dim
        S1 = cut.S1
        p, q = ufl.TrialFunction(S1), ufl.TestFunction(S1)
        self._a = TaggedForm((1.0 / density) * ufl.inner(ufl.grad(p), ufl.grad(q)) * cut.dx)
        fdim = mesh.topology.dim - 1
        mesh.topology.create_connectivity(fdim, fdim + 1)
        if open_facets is None:
            open_facets = np.zeros(0, np.int32)
        open_facets = np.asarray(open_facets, np.int32)
        if self.comm.allreduce(open_facets.size, op=MPI.SUM) > 0:
            dofs = fem.locate_dofs_topological(S1, fdim, open_facets)
        else:                     # closed container: p = 0 at the node nearest the lower corner
            lo = mesh_extent(mesh)[0]
            X = S1.tabulate_dof_coordinates()[:, :gdim]
            nown = S1.dofmap.index_map.size_local
            d = np.linalg.norm(X[:nown] - lo, axis=1) if nown else np.array([np.inf])
            best = self.comm.allreduce((float(d.min()), self.comm.rank), op=MPI.MINLOC)
            dofs = np.array([int(np.argmin(d))], np.int32) if self.comm.rank == best[1] else np.zeros(0, np.int32)
        self._bc = fem.dirichletbc(PETSc.ScalarType(0.0), dofs, S1)
        self._A = fem.petsc.create_matrix(self._a.form)
        direct = gdim == 2 or S1.dofmap.index_map.size_global <= POISSON_3D_DIRECT_LIMIT
        self._ksp = make_ksp(self.comm, self._A, "added_mass_", POISSON_2D if direct else POISSON_3D)
        # C_f: rows DG0 (cells), columns P1; f = n_j (j < gdim), then (x × n) (1 in 2D, 3 in 3D)
        D0 = fem.FunctionSpace(mesh, ("DG", 0))
        v0 = ufl.TestFunction(D0)
        n = cut.wall_normal()
        x = ufl.SpatialCoordinate(mesh)
        if gdim == 2:
            moments = [x[0] * n[1] - x[1] * n[0]]
        else:
            xn = ufl.cross(x, n)
            moments = [xn[k] for k in range(3)]
        self._c_forms = [TaggedForm(f * p * v0 * cut.dGamma) for f in [n[j] for j in range(gdim)] + moments]
        # stored zeros on every cell: the cut cells move, and PETSc drops entries outside the
        # structure of the first assembly
        zero = jit.form(fem.Constant(mesh, PETSc.ScalarType(0.0)) * p * v0 * cut.dx_q)
        self._C = [fem.petsc.assemble_matrix(zero) for _ in self._c_forms]
        for C in self._C:
            C.assemble()
        self.chi = fem.Function(D0)
        self._dg0_dofs = D0.dofmap.list.array           # cell → DG0 dof (owned cells first)
        self._b = [fem.petsc.create_vector(jit.form(q * cut.dx)) for _ in range(rigid_modes(gdim))]
        self._p = self._b[0].duplicate()
        self._tmp = self._b[0].duplicate()
        self.last_solves = 0

    def assemble(self) -> None:
        """Laplacian and the C_f of the current cut and density (call once per fluid step)."""
        self._A.zeroEntries()
        fem.petsc.assemble_matrix(self._A, self._a.form, bcs=[self._bc])
        self._A.assemble()
        self._ksp.setOperators(self._A)
        for C, form in zip(self._C, self._c_forms):
            C.zeroEntries()
            fem.petsc.assemble_matrix(C, form.form)
            C.assemble()

    def tensors(self, weights: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """Added-mass tensors (ng, modes, modes) [kg, kg m, kg m²; 2D: per unit depth] of ng
        groups: ``weights`` (ng, n_local_cells) the share of every local cell's surface that
        belongs to each group (0…1; owned cells are what counts), ``centres`` (ng, 3) the
        points the rotation modes turn about. Modes: translations x, y(, z), then rotations
        about z (2D) or x, y, z (3D). A group without cut surface gets zeros. Collective."""
        gdim, nm = self.gdim, rigid_modes(self.gdim)
        ng = len(weights)
        out = np.zeros((ng, nm, nm))
        own = self.cut.n_owned
        dofs = self._dg0_dofs[:own]
        self.last_solves = 0
        for g in range(ng):
            self.chi.x.array[:] = 0.0
            self.chi.x.array[dofs] = weights[g][:own]
            chi, tmp = self.chi.vector, self._tmp
            X = np.asarray(centres[g], float)
            for k in range(nm):
                b = self._b[k]
                if k < gdim:
                    self._C[k].multTranspose(chi, b)
                else:
                    # rotation about X: (x − X) × n = x × n − X × n
                    if gdim == 2:
                        self._C[2].multTranspose(chi, b)
                        self._C[1].multTranspose(chi, tmp)            # − X n_y
                        b.axpy(-X[0], tmp)
                        self._C[0].multTranspose(chi, tmp)            # + Y n_x
                        b.axpy(X[1], tmp)
                    else:
                        r = k - 3
                        self._C[3 + r].multTranspose(chi, b)
                        i, j = (r + 1) % 3, (r + 2) % 3               # (X × n)_r = X_i n_j − X_j n_i
                        self._C[j].multTranspose(chi, tmp)
                        b.axpy(-X[i], tmp)
                        self._C[i].multTranspose(chi, tmp)
                        b.axpy(X[j], tmp)
                b.scale(-1.0)                                         # rhs −∫ (m·n) q dΓ
                fem.petsc.set_bc(b, [self._bc])
            norms = [b.norm() for b in self._b]
            if max(norms) == 0.0:
                continue
            for k in range(nm):
                if norms[k] == 0.0:
                    continue
                solve_ksp(self._ksp, self._b[k], self._p)
                self.last_solves += 1
                for j in range(nm):
                    out[g, j, k] = self._p.dot(self._b[j])
        # symmetric up to the solver tolerance; keep the symmetric part
        return 0.5 * (out + out.transpose(0, 2, 1))

    def destroy(self) -> None:
        for obj in [self._A, self._ksp, self._p, self._tmp, *self._C, *self._b]:
            obj.destroy()


def largest_eigenvalue(sym: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of each symmetric matrix in the stack (…, n, n), ≥ 0."""
    return np.maximum(np.linalg.eigvalsh(sym)[..., -1], 0.0)


class AddedMassStage:
    """The added-mass stabilisation of the explicit coupling (module docstring of
    ``simulation.coupled``): per block m̃ (raising the DEM mass) and Ĩ (its inertia), set
    every step, and the lagged load m̃ aⁿ − m̃ g (+ R Ĩ Rᵀ αⁿ) the DEM gets on top of the
    fluid's (relaxed) load. Owns the blocks' own mass and inertia, the last step's
    accelerations and the relaxed load. ``system`` the DEM system, ``cut`` the cut domain,
    ``rho`` the fluid density field (a Function or Constant), ``natural_facets`` the fluid's
    open boundaries, ``depth`` [m] the span of a 2D fluid (1 in 3D); ``volume_ratio``,
    ``gyration_ratio`` (nb,) the fluid-seen shape's volume and squared radius of gyration over
    the block's own (``coupling.min_thickness``). With the flow's added mass and ``out_dir``,
    rank 0 writes ``added_mass.csv`` (t, block, m̃, the largest Ĩ, solves)."""

    def __init__(self, case, system, cut, rho, natural_facets, gdim: int, depth: float,
                 volume_ratio: np.ndarray, gyration_ratio: np.ndarray, out_dir=None, rank: int = 0) -> None:
        self.case, self.system, self.cut, self.rho = case, system, cut, rho
        self.natural_facets, self.gdim, self.depth = natural_facets, gdim, depth
        cp = case.coupling
        self.factor, self.model, self.relaxation = cp.added_mass, cp.added_mass_model, cp.force_relaxation
        st = system.state
        self.nb = st.nb
        self.mass0, self.inertia0 = st.mass.copy(), st.inertia.copy()
        #: V_b, the block's volume as the fluid sees it (m_b/ρ_material × the min_thickness widening)
        self.volume_b = block_volume(case.dem, st) * volume_ratio
        with np.errstate(invalid="ignore", divide="ignore"):   # fixed blocks: no added mass
            k2 = self.inertia0 / self.mass0[:, None] * gyration_ratio
        self.gyration_sq = np.where(np.isfinite(k2), k2, 0.0)
        self.added_mass = np.zeros(self.nb)          # m̃ per block, set every step
        self.added_inertia = np.zeros((self.nb, 3))   # Ĩ per block (body axes)
        self.added_tensor = None                      # (nb, 3, 3) M̃ per block (added_mass_model: tensor)
        self._potential = None                        # added_mass_model: potential (built at first use)
        self._flow_added_mass = None                  # the last flow-computed result (a step's passes share it)
        self.accel = np.zeros((self.nb, 3))           # a and α of the last fluid step
        self.alpha = np.zeros((self.nb, 3))
        self.relaxed_load = np.zeros((2 * self.nb, 3))   # force; torque applied last step (force_relaxation)
        self.csv = None
        if out_dir is not None and self.from_flow and self.factor > 0:
            from ..io.csv import TimeSeriesCSV
            self.csv = TimeSeriesCSV(Path(out_dir) / "added_mass.csv", {"t": "s", "block": "-", "m_tilde": "kg",
                                                                        "i_tilde": "kg m^2", "solves": "-"},
                                     rank, lazy=True)

    @property
    def from_flow(self) -> bool:
        """Whether m̃ comes from the flow's added-mass tensor (``added_mass_model`` potential or tensor)."""
        return self.model in ("potential", "tensor")

    def update(self, t: float, labels: np.ndarray | None, same_poses: bool = False) -> None:
        """m̃_b = C_a ρ̄_b V_b with ρ̄_b the mean fluid density on block b's wetted (cut)
        surface, so a block in air carries C_a ρ_air V_b, not the water's (with the water's,
        the lagged m̃ aⁿ term turned floor-contact chatter into a load of several times the
        weight of a block resting in air); 0 for blocks without cut surface and fixed blocks;
        or from the flow (:meth:`_potential_added_mass`, ``labels`` the moving groups; only then
        needed).
        Raises the DEM mass and inertia (by Ĩ = m̃ k², k the fluid-seen shape's radius of
        gyration) for the coming sub-steps. ``same_poses``: a later pass of the implicit
        coupling, whose flow-computed m̃ is the first pass's (same cut and clusters; φ inside
        the blocks, which ρ carries into it, moves with each pass's ū: 7e-7 of a block's
        velocity per step, tests/simulation/test_coupled.py)."""
        if self.factor == 0.0:
            return
        st = self.system.state
        if self.from_flow:
            if not same_poses or self._flow_added_mass is None:
                self._flow_added_mass = self._potential_added_mass(t, labels)
            extra, extra_inertia, self.added_tensor = self._flow_added_mass
        else:
            # (negative fitted surface weights can overshoot a sharp ρ jump slightly: clip at 0)
            rho_bar = np.maximum(np.nan_to_num(self.cut.wetted_mean(self.nb, self.rho), nan=0.0), 0.0)
            extra = self.factor * rho_bar * self.volume_b
            extra[st.fixed] = 0.0
            extra_inertia = extra[:, None] * self.gyration_sq
        self.added_mass, self.added_inertia = extra, extra_inertia
        st.mass[:] = self.mass0 + extra
        st.inertia[:] = self.inertia0 + extra_inertia
        if self.added_tensor is not None:
            # the kick's inverse of m I + M̃ (st.mass = m + λ_min(M̃) carries gravity, the contact
            # dashpots and Δt_cr: the lightest direction); fixed blocks are not kicked
            free = ~st.fixed
            tens = self.added_tensor.copy()
            tens[free] += self.mass0[free, None, None] * np.eye(3)[None]
            tens[~free] = np.eye(3)[None]
            self.system.inv_mass = np.linalg.inv(tens)

    def _potential_added_mass(self, t: float, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``added_mass_model: potential``: m̃ (nb,) [kg] and Ĩ (nb, 3) [kg m²] per block from
        the added-mass tensor M of each moving group (``labels``: block, or bonded cluster with
        ``wall_motion: bonded_cluster``) on the current cut (:class:`PotentialAddedMass`):
        m̃_group = factor × λ_max(M_translation), shared over its blocks by fluid-seen volume;
        the rotational λ_max(M_rotation) about the group's centre of mass, less what the shared
        m̃ already gives at the blocks' offsets, shared alike as Ĩ on every axis. Groups
        holding a fixed block get none. Writes added_mass.csv. ``tensor``: m̃ is factor ×
        λ_min(M_translation) shared alike, and the third result is each block's share of
        factor × M_translation (nb, 3, 3) (None with ``potential``)."""
        st, factor = self.system.state, self.factor
        if self._potential is None:
            self._potential = PotentialAddedMass(self.cut, self.rho, self.natural_facets)
        pot = self._potential
        groups = [g for g in np.unique(labels) if not st.fixed[labels == g].any()]
        extra, extra_inertia = np.zeros(self.nb), np.zeros((self.nb, 3))
        tensor = self.model == "tensor"
        added_tensor = np.zeros((self.nb, 3, 3)) if tensor else None
        if not groups:
            return extra, extra_inertia, added_tensor
        pot.assemble()
        ncell = len(self.cut.cell_owner)
        owner, second, share = self.cut.cell_owner, self.cut.cell_second, self.cut.cell_share
        weights = np.zeros((len(groups), ncell))
        centres = np.zeros((len(groups), 3))
        for i, g in enumerate(groups):
            inside = labels == g
            in_first = (owner >= 0) & inside[np.maximum(owner, 0)]
            in_second = (second >= 0) & inside[np.maximum(second, 0)]
            weights[i] = np.where(in_first, 1.0 - share, 0.0) + np.where(in_second, share, 0.0)
            m = self.mass0[inside]
            centres[i] = (m[:, None] * st.pos[inside]).sum(axis=0) / m.sum()
        M = pot.tensors(weights, centres) * self.depth
        d = self.gdim
        if tensor:   # the translational tensor itself; the scalar part is its smallest eigenvalue
            m_group = factor * np.maximum(np.linalg.eigvalsh(M[:, :d, :d])[:, 0], 0.0)
        else:
            m_group = factor * largest_eigenvalue(M[:, :d, :d])
        j_group = factor * largest_eigenvalue(M[:, d:, d:])
        for i, g in enumerate(groups):
            blocks = np.flatnonzero(labels == g)
            share_b = self.volume_b[blocks] / self.volume_b[blocks].sum()
            extra[blocks] = m_group[i] * share_b
            if tensor:
                added_tensor[blocks, :d, :d] = factor * share_b[:, None, None] * M[i, :d, :d][None]
            r = st.pos[blocks] - centres[i]
            if d == 2:
                carried = float((extra[blocks] * (r[:, 0] ** 2 + r[:, 1] ** 2)).sum())
            else:       # about the axis where the shared masses carry least
                carried = float(min((extra[blocks] * ((r ** 2).sum(axis=1) - r[:, k] ** 2)).sum() for k in range(3)))
            extra_inertia[blocks] = max(j_group[i] - carried, 0.0) * share_b[:, None]
        if self.csv is not None:
            for b in range(self.nb):
                if extra[b] > 0:
                    self.csv.write(t=t, block=b, m_tilde=extra[b], i_tilde=extra_inertia[b].max(),
                                   solves=pot.last_solves)
        return extra, extra_inertia, added_tensor

    def load(self, force: np.ndarray, torque: np.ndarray, accel: np.ndarray,
             alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The DEM's load: the fluid's ``force``, ``torque`` (nb, 3) relaxed (ω F + (1 − ω) × the
        last relaxed load) + m̃ aⁿ − m̃ g and torque + R Ĩ Rᵀ αⁿ, ``accel``, ``alpha`` the
        accelerations the fluid answers (:attr:`accel`, :attr:`alpha`, or their bonded
        clusters' rigid parts)."""
        w = self.relaxation
        if w < 1.0:
            self.relaxed_load[:] = w * np.concatenate([force, torque]) + (1.0 - w) * self.relaxed_load
            force, torque = self.relaxed_load[: self.nb], self.relaxed_load[self.nb:]
        if not self.added_mass.any() and (self.added_tensor is None or not self.added_tensor.any()):
            return force.copy(), torque.copy()
        st = self.system.state
        g = np.asarray(self.case.dem.gravity)
        if self.added_tensor is not None:    # M̃ aⁿ − m̃ g (m̃ = λ_min(M̃) is in the DEM's scalar mass)
            F = force + np.einsum("bij,bj->bi", self.added_tensor, accel) - self.added_mass[:, None] * g[None, :]
        else:
            F = force + self.added_mass[:, None] * (accel - g[None, :])
        R = st.rotation_matrices()
        body = np.einsum("bji,bj->bi", R, alpha) * self.added_inertia
        T = torque + np.einsum("bij,bj->bi", R, body)
        return F, T

    def record(self, v0: np.ndarray, w0: np.ndarray, v1: np.ndarray, w1: np.ndarray, dt: float) -> None:
        """aⁿ, αⁿ: the change over a fluid step ``dt`` [s] of the wall velocity the fluid got
        (``v0``, ``w0``) against the one it gets next step (``v1``, ``w1``): what the fluid's
        added-mass reaction answers, so m̃ aⁿ cancels it."""
        self.accel[:] = (v1 - v0) / dt
        self.alpha[:] = (w1 - w0) / dt

    def arrays(self) -> dict[str, np.ndarray]:
        """What it carries between steps (checkpoint globals, retry snapshot)."""
        return {"coupling__accel": np.concatenate([self.accel, self.alpha]),
                "coupling__relaxed_load": self.relaxed_load.copy()}

    def resume(self, time: float) -> None:
        """Continue ``added_mass.csv`` of the run a checkpoint at ``time`` [s] came from."""
        if self.csv is not None:
            self.csv.resume(time)

    def load_arrays(self, g: dict[str, np.ndarray]) -> None:
        """Inverse of :meth:`arrays`."""
        self.accel[:], self.alpha[:] = g["coupling__accel"][: self.nb], g["coupling__accel"][self.nb:]
        if "coupling__relaxed_load" in g:
            self.relaxed_load[:] = g["coupling__relaxed_load"]
