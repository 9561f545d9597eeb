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

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from ..fluid.solvers import DIRECT_LU, make_ksp
from ..fluid.solvers import solve as solve_ksp
from ..fluid.tagged_form import TaggedForm

#: solver of the pressure-impulse Laplacian (a symmetric positive definite P1 system)
POISSON_2D = dict(DIRECT_LU)
POISSON_3D = {"ksp_type": "cg", "ksp_rtol": 1e-8, "ksp_max_it": 2000, "pc_type": "hypre",
              "pc_hypre_type": "boomeramg"}


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
            x = mesh.geometry.x[:, :gdim]
            lo = self.comm.allreduce(x.min(axis=0, initial=np.inf) if len(x) else np.full(gdim, np.inf), op=MPI.MIN)
            X = S1.tabulate_dof_coordinates()[:, :gdim]
            nown = S1.dofmap.index_map.size_local
            d = np.linalg.norm(X[:nown] - lo, axis=1) if nown else np.array([np.inf])
            best = self.comm.allreduce((float(d.min()), self.comm.rank), op=MPI.MINLOC)
            dofs = np.array([int(np.argmin(d))], np.int32) if self.comm.rank == best[1] else np.zeros(0, np.int32)
        self._bc = fem.dirichletbc(PETSc.ScalarType(0.0), dofs, S1)
        self._A = fem.petsc.create_matrix(self._a.form)
        self._ksp = make_ksp(self.comm, self._A, "added_mass_", POISSON_2D if gdim == 2 else POISSON_3D)
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
        zero = fem.form(fem.Constant(mesh, PETSc.ScalarType(0.0)) * p * v0 * cut.dx_q)
        self._C = [fem.petsc.assemble_matrix(zero) for _ in self._c_forms]
        for C in self._C:
            C.assemble()
        self.chi = fem.Function(D0)
        self._dg0_dofs = D0.dofmap.list.array           # cell → DG0 dof (owned cells first)
        self._b = [fem.petsc.create_vector(fem.form(q * cut.dx)) for _ in range(rigid_modes(gdim))]
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
