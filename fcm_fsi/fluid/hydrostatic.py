"""Well-balanced gravity: a P2 static pressure Π carried next to the P1 pressure.

With a density field ρ(φ) the P1 pressure cannot balance ρ g where ρ varies inside a cell:
at rest the Galerkin and PSPG terms then leave a residual that drives spurious currents,
largest in the light phase (docs/two-phase.md). We split the pressure

    p = p' + Π,   Π ∈ P2 (continuous, piecewise quadratic),

where Π is the gradient part of the body force, the Neumann projection

    (∇Π, ∇s) = (ρ f, ∇s)  for all s ∈ P2,    Π = 0 on natural (do-nothing) boundaries,

(with no natural boundary, Π = 0 at the node where the solver pins p' = 0 instead).
Every term of eq 5 that contains the pressure uses p' + Π. The continuous equations are
unchanged (any Π is a change of the pressure unknown), the discrete ones are not: the discrete
pressure now lives in Π + P1 instead of P1, which contains the exact hydrostatic pressure of a
layered fluid. For layered ρ (a fluid at rest: ρ depends on the height only; on a mesh whose nodes
lie in horizontal layers its P1 interpolant is then exactly the gradient of a P2 Π) the
discrete rest state u = 0, p' = 0 is then exact, and near rest the residual that drives
spurious currents is the curl part of ρ f only. In motion the two discretisations differ by
discretisation error (tested on the verification cases).

Cost: one P2 Poisson solve per time step when ρ changes: in 2D triangular solves with the factorisation
made once (PETSc Cholesky on one rank, MUMPS on more), in 3D CG + BoomerAMG.
"""
from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from .. import jit
from . import solvers

#: P2 Poisson solve; tight, because the solve error of Π acts as a force on the fluid. The matrix
#: never changes, so the factorisation is made once and each update is a pair of triangular
#: solves: on one rank PETSc's own Cholesky (nested dissection) does them ≈ 4× faster than MUMPS
DIRECT = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
DIRECT_SERIAL = {"ksp_type": "preonly", "pc_type": "cholesky", "pc_factor_mat_solver_type": "petsc",
                 "pc_factor_mat_ordering_type": "nd"}
ITERATIVE = {"ksp_type": "cg", "ksp_rtol": 1e-12, "ksp_atol": 1e-14, "ksp_max_it": 500,
             "pc_type": "hypre", "pc_hypre_type": "boomeramg"}


def static_pressure_space(mesh) -> fem.FunctionSpace:
    """The P2 space of Π."""
    return fem.FunctionSpace(mesh, ("Lagrange", 2))


class StaticPressure:
    """Π of the module docstring for the NavierStokes solver ``ns`` built with ``static_pressure=Pi``.

    ``rho`` is the density Function (kg/m³) the Navier–Stokes forms use, ``gravity`` the body
    force per unit mass (m/s²). Call :meth:`update` whenever ρ has changed.
    """

    def __init__(self, ns, Pi: fem.Function, rho, gravity: np.ndarray) -> None:
        self.ns, self.Pi, self.comm = ns, Pi, ns.comm
        mesh = ns.mesh
        P2 = Pi.function_space
        f = fem.Constant(mesh, np.asarray(gravity, dtype=PETSc.ScalarType))
        Pt, s = ufl.TrialFunction(P2), ufl.TestFunction(P2)
        dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 2})
        self._a = jit.form(ufl.inner(ufl.grad(Pt), ufl.grad(s)) * dx)
        self._L = jit.form(ufl.inner(rho * f, ufl.grad(s)) * dx)
        fdim = mesh.topology.dim - 1
        natural = ns.bc_set.natural_facets
        if ns.comm.allreduce(len(natural), op=MPI.SUM):
            dofs = fem.locate_dofs_topological(P2, fdim, natural)
        else:   # closed domain: Π = 0 where p' is pinned (the source is compatible, so this is exact)
            target = np.asarray(ns.bc_set.pinned_point)
            gdim = mesh.geometry.dim
            tol = 1e-12 * max(1.0, float(np.abs(target).max()))
            dofs = fem.locate_dofs_geometrical(
                P2, lambda x: np.linalg.norm(x[:gdim].T - target[:gdim], axis=1) <= tol)
        self.bcs = [fem.dirichletbc(PETSc.ScalarType(0.0), dofs, P2)]
        self.A = fem.petsc.assemble_matrix(self._a, bcs=self.bcs)
        self.A.assemble()
        self.b = fem.petsc.create_vector(self._L)
        direct = DIRECT_SERIAL if self.comm.size == 1 else DIRECT
        opts = dict(direct if mesh.geometry.dim == 2 else ITERATIVE)
        self.ksp = solvers.make_ksp(self.comm, self.A, "static_p_", opts)
        self.p1 = fem.Function(ns.Q)   # Π interpolated to the P1 pressure nodes (output)

    def update(self) -> None:
        """Solve for Π from the current ρ (collective)."""
        with self.b.localForm() as loc:
            loc.set(0.0)
        fem.petsc.assemble_vector(self.b, self._L)
        fem.petsc.apply_lifting(self.b, [self._a], bcs=[self.bcs])
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fem.petsc.set_bc(self.b, self.bcs)
        solvers.solve(self.ksp, self.b, self.Pi.vector)
        solvers.check_converged(self.ksp, self.ns.step_count, self.ns.t)
        self.Pi.x.scatter_forward()
        self.p1.interpolate(self.Pi)

    def total_pressure(self, p_dynamic: np.ndarray) -> np.ndarray:
        """p' + Π at the P1 pressure nodes [Pa]."""
        return p_dynamic + self.p1.x.array
