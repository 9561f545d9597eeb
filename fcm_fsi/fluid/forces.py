"""Forces on boundaries by the variational reaction of the momentum residual, and point probes.

For a converged discrete solution the residual R(w) of eq 5 vanishes for every test w that
is zero on Dirichlet boundaries. Testing with w = e_i on the nodes of a body boundary Γ
(zero elsewhere, q = 0) gives R(w) = ∫_Γ (σ n_f)·e_i dΓ with n_f the fluid's outward normal,
so the force of the fluid on the body is F_i = −R(w). This is the consistent ("reaction")
force: it includes the stabilization terms and is second-order accurate for P1, unlike
a surface integral of σ·n of the P1 gradients.
"""
from __future__ import annotations

import numpy as np
from dolfinx import fem, geometry
from mpi4py import MPI
from petsc4py import PETSc


class ReactionForce:
    """Force (N, or N/m in 2D) of the fluid on the nodes of ``facets`` for residual form ``F_form``;
    ``W`` is the (u, p) space (:func:`.navier_stokes.velocity_pressure_space`)."""

    def __init__(self, W: fem.FunctionSpace, F_form: fem.FormMetadata, facets: np.ndarray) -> None:
        mesh = W.mesh
        fdim = mesh.topology.dim - 1
        self.F_form = F_form
        self.b = fem.petsc.create_vector(F_form)
        self.indicators = []
        for i in range(mesh.geometry.dim):
            Vi, _ = W.sub(i).collapse()
            dofs = fem.locate_dofs_topological((W.sub(i), Vi), fdim, facets)[0]
            e = fem.Function(W)
            e.x.array[dofs] = 1.0
            self.indicators.append(e)

    def __call__(self) -> np.ndarray:
        """Assemble the residual at the current state and return the force vector (collective)."""
        with self.b.localForm() as loc:
            loc.set(0.0)
        fem.petsc.assemble_vector(self.b, self.F_form)
        self.b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return np.array([-self.b.dot(e.vector) for e in self.indicators])


def probe(fn: fem.Function, points: np.ndarray) -> np.ndarray:
    """Values of ``fn`` at ``points`` (n × 3) on every rank; NaN where no rank owns the point."""
    mesh = fn.function_space.mesh
    comm = mesh.comm
    points = np.atleast_2d(np.asarray(points, dtype=float))
    tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
    cands = geometry.compute_collisions(tree, points)
    cells = geometry.compute_colliding_cells(mesh, cands, points)
    nown = mesh.topology.index_map(mesh.topology.dim).size_local
    vs = fn.ufl_shape[0] if fn.ufl_shape else 1
    local = np.full((len(points), vs), np.nan)
    for i in range(len(points)):
        links = cells.links(i)
        links = links[links < nown]
        if len(links):
            local[i] = fn.eval(points[i], links[:1])
    found = np.where(np.isnan(local), 0.0, local)
    count = (~np.isnan(local)).astype(float)
    tot = comm.allreduce(found, op=MPI.SUM)
    cnt = comm.allreduce(count, op=MPI.SUM)
    with np.errstate(invalid="ignore"):
        out = tot / cnt
    return out[:, 0] if vs == 1 else out
