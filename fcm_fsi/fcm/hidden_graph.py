"""The harmonic extension of the hidden samples' pressure over their surface graph
(``coupling.hidden_pressure``, fcm/hidden.py): the graphs' conductances, the Laplacian of the
hidden samples with the wetted ones as Dirichlet values (:class:`HiddenGraph`), and its solver
(:class:`LaplaceSolver`).

The Reynolds equation of a thin gap of uniform opening is Laplace's equation on the surface; on
a graph of the samples it is Σ_j c_ij (v_j − v_i) = 0 at each hidden sample i. Water at rest has
one piezometric pressure per fluid, which any such interpolation keeps exactly.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

#: samples closer than this × the spacing are neighbours in the surface graph (a sample
#: grid's diagonal neighbours are at √2 spacings at most)
GRAPH_REACH = 1.6


def symmetric_graph(i: np.ndarray, j: np.ndarray, c: np.ndarray, n: int) -> sp.csr_matrix:
    """The (n, n) conductance matrix with c on the links (i, j) and (j, i)."""
    return sp.coo_matrix((np.concatenate([c, c]), (np.concatenate([i, j]), np.concatenate([j, i]))),
                         shape=(n, n)).tocsr()


def chain_conductance(lengths: np.ndarray) -> sp.csr_matrix:
    """The closed chain of samples of one curve (cyclic order) with conductance
    1/(arc distance) between consecutive midpoints: its harmonic functions are linear in arc
    length."""
    n = len(lengths)
    i = np.arange(n)
    j = (i + 1) % n
    c = 2.0 / (lengths[i] + lengths[j])
    return symmetric_graph(i, j, c, n)


def radius_conductance(points: np.ndarray, spacing: float) -> sp.csr_matrix:
    """Samples closer than :data:`GRAPH_REACH` × ``spacing`` linked with conductance
    1/distance² (on a uniform grid the five-point Laplacian)."""
    pairs = cKDTree(points).query_pairs(GRAPH_REACH * spacing, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    c = 1.0 / np.sum((points[i] - points[j]) ** 2, axis=1)
    n = len(points)
    return symmetric_graph(i, j, c, n)


#: graph Laplacians with more unknowns than this are solved by preconditioned CG, smaller ones by
#: sparse LU (whose fill-in makes the 10⁵ hidden samples of a building's joints slow)
DIRECT_LIMIT = 5000
#: the CG preconditioner of the larger graph Laplacians, and the tolerance relative to ‖rhs‖. On the
#: tsunami building's 74,000 joint samples the extension at this tolerance is within 5e-6 of its range
#: of the converged one (a tenth of what the pressures change by from one implicit pass to the next),
#: the blocks' hidden load after a step of six passes within 1e-6 of its magnitude of the load at
#: 1e-8; from the last pass's solution CG takes 4 iterations where 1e-8 takes 19. In `verify buoyancy`
#: (full) the lifts are those at 1e-8 to 6 digits and the flat blocks' horizontal loads rise from 1e-9 to
#: 4e-7 of ρ g V (the check allows 1e-2)
GRAPH_PC = "icc"
GRAPH_RTOL = 1e-6


class LaplaceSolver:
    """L x = rhs for the SPD graph Laplacian ``L`` of the hidden samples (Dirichlet rows of the
    mouths eliminated), one column of ``rhs`` (n, k) at a time; every rank holds the same
    (replicated) system. Small systems by sparse LU on every rank; larger ones by CG with
    :data:`GRAPH_PC`, column j on rank j mod size of ``comm`` (the same arithmetic on any number
    of ranks), the preconditioner kept while the graph's links stay the same (a structure at
    rest: only the conductances' values and the mouths' pressures change from step to step).
    Each solve starts from the last solution of the same samples (``ids``, their indices among
    all samples; samples new to the hidden set from the mean of the last solution): the hidden
    set changes by a few samples at the mouths from step to step, and the solution changes
    little. A matrix passed again as the same object is taken as unchanged (a
    :class:`HiddenGraph` extended for the later passes of an implicit step)."""

    def __init__(self, comm=None) -> None:
        self.comm = comm
        self._pattern = None         # (indptr, indices) of the matrix the preconditioner was built for
        self._ksp = self._A = None
        self._source = None          # the matrix object the operator holds (the same object: values unchanged)
        self._last_ids = None        # sample indices of the last solve (sorted)
        self._last = None            # (n, k) last solutions

    def _guess(self, ids: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
        """The last solution at ``ids`` (the mean of the last solution where a sample is new)."""
        if self._last is None or self._last.shape[1] != shape[1]:
            return None
        if ids is None:
            return self._last if self._last.shape == shape else None
        at = np.searchsorted(self._last_ids, ids)
        at = np.minimum(at, len(self._last_ids) - 1)
        known = self._last_ids[at] == ids
        return np.where(known[:, None], self._last[at], self._last.mean(axis=0)[None, :])

    def solve(self, L: sp.csr_matrix, rhs: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray:
        if L.shape[0] <= DIRECT_LIMIT:
            return np.reshape(spsolve(L.tocsc(), rhs), rhs.shape)
        rank, size = (0, 1) if self.comm is None else (self.comm.rank, self.comm.size)
        columns = range(rank, rhs.shape[1], size)
        out = np.zeros_like(rhs)
        self.iterations = 0
        if len(columns):
            self._solve_columns(L, rhs, ids, columns, out)
        if size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        self._last = out.copy()
        self._last_ids = None if ids is None else np.asarray(ids).copy()
        return out

    def _solve_columns(self, L: sp.csr_matrix, rhs: np.ndarray, ids, columns, out: np.ndarray) -> None:
        """CG for the ``columns`` of ``rhs`` into ``out``."""
        same = self._set_operator(L)
        ksp = self._ksp
        ksp.setOperators(self._A)
        ksp.getPC().setReusePreconditioner(same)
        guess = self._guess(ids, rhs.shape)
        ksp.setInitialGuessNonzero(guess is not None)
        x, b = self._A.createVecs()
        for k in columns:
            b.array[:] = rhs[:, k]
            x.array[:] = guess[:, k] if guess is not None else 0.0
            ksp.solve(b, x)
            if ksp.getConvergedReason() <= 0:
                raise RuntimeError(f"hidden-surface pressure: CG did not converge ({ksp.getConvergedReason()})")
            self.iterations += ksp.getIterationNumber()
            out[:, k] = x.array
        x.destroy(), b.destroy()

    def _set_operator(self, L: sp.csr_matrix) -> bool:
        """``L`` as the PETSc operator; returns whether the preconditioner is kept: ``L`` is the
        last solve's matrix object (a later pass of the same graph: nothing to set) or has its
        links (new values set); else a new operator, CG and preconditioner."""
        from petsc4py import PETSc
        if L is self._source:
            return True
        source, L = L, sp.csr_matrix(L)
        L.sort_indices()
        indptr, indices = L.indptr.astype(PETSc.IntType), L.indices.astype(PETSc.IntType)
        same = self._pattern is not None and np.array_equal(self._pattern[0], L.indptr) \
            and np.array_equal(self._pattern[1], L.indices)
        if same:
            self._A.setValuesCSR(indptr, indices, L.data)
            self._A.assemble()
        else:
            self._free_operator()
            self._A = PETSc.Mat().createAIJ(size=L.shape, csr=(indptr, indices, L.data), comm=PETSc.COMM_SELF)
            self._ksp = PETSc.KSP().create(PETSc.COMM_SELF)
            self._ksp.setType("cg")
            self._ksp.getPC().setType(GRAPH_PC)
            self._ksp.setTolerances(rtol=GRAPH_RTOL, atol=0.0, max_it=2000)
            self._pattern = (L.indptr.copy(), L.indices.copy())
        self._source = source
        return same

    def _free_operator(self) -> None:
        for obj in (self._ksp, self._A):
            if obj is not None:
                obj.destroy()
        self._ksp = self._A = self._pattern = self._source = None

    def destroy(self) -> None:
        self._free_operator()
        self._last = self._last_ids = None



class HiddenGraph:
    """The Laplacian of the ``hidden`` samples (n,) on the sample graph of ``conductance``
    (n, n), the wetted samples' values its Dirichlet data: what the hidden set and the graph
    fix, so that several sets of values (the passes of an implicit step, in which the blocks
    stand still) are extended on one system. Hidden samples with no path to a wetted one are
    not reached."""

    def __init__(self, hidden: np.ndarray, conductance: sp.spmatrix) -> None:
        hidden = np.asarray(hidden, bool)
        self.H, self.W = np.flatnonzero(hidden), np.flatnonzero(~hidden)
        self.reached = np.zeros(0, bool)
        self.L = self.B = None
        if self.H.size == 0:
            return
        rows = sp.csr_matrix(conductance)[self.H]
        A, B = rows[:, self.H], rows[:, self.W]
        to_wet = np.asarray(B.sum(axis=1)).ravel()
        ncomp, label = connected_components(A, directed=False)
        self.reached = (np.bincount(label, weights=to_wet, minlength=ncomp) > 0)[label]
        if self.reached.any():
            A, self.B = A[self.reached][:, self.reached], B[self.reached]
            self.L = (sp.diags(np.asarray(A.sum(axis=1)).ravel() + to_wet[self.reached]) - A).tocsr()

    def extend(self, values: np.ndarray, solver: LaplaceSolver | None = None) -> np.ndarray:
        """``values`` (n,) or (n, k) at every sample: wetted samples keep theirs, hidden ones
        get the harmonic extension of the wetted values (NaN where not reached), solved by
        ``solver`` (a fresh :class:`LaplaceSolver` by default)."""
        out = np.array(values, dtype=float, copy=True)
        H = self.H
        if H.size == 0:
            return out
        out[H[~self.reached]] = np.nan
        if self.L is not None:
            rhs = self.B @ out[self.W]
            solver = LaplaceSolver() if solver is None else solver
            out[H[self.reached]] = solver.solve(self.L, rhs.reshape(len(rhs), -1), H[self.reached]).reshape(rhs.shape)
        return out


def interpolate_hidden(hidden: np.ndarray, values: np.ndarray, conductance: sp.spmatrix,
                       solver: LaplaceSolver | None = None) -> np.ndarray:
    """``values`` (n,) or (n, k) at every sample: wetted samples keep theirs, hidden ones get
    the harmonic extension of the wetted values over the sample graph of ``conductance``
    (n, n) (Σ_j c_ij (v_j − v_i) = 0 at each hidden sample), solved by ``solver`` (a fresh
    :class:`LaplaceSolver` by default). Hidden samples with no path to a wetted one: NaN."""
    return HiddenGraph(hidden, conductance).extend(values, solver)


def piezometric_extension(graph: HiddenGraph, p: np.ndarray, rho: np.ndarray, gx: np.ndarray,
                          solver: LaplaceSolver | None = None) -> np.ndarray:
    """Pressure [Pa] at the samples: wetted ones keep ``p``; on the hidden ones of ``graph``
    the piezometric pressure p − ρ g·x and the density ρ are extended from the mouths and
    p = (p − ρ g·x) + ρ g·x at the sample (``gx`` = g·x [m²/s²] per sample). Exact for water
    at rest whatever the path."""
    both = graph.extend(np.column_stack([p - rho * gx, rho]), solver)
    return both[:, 0] + both[:, 1] * gx


def hidden_pressure(hidden: np.ndarray, p: np.ndarray, rho: np.ndarray, gx: np.ndarray,
                    conductance: sp.spmatrix, solver: LaplaceSolver | None = None) -> np.ndarray:
    """:func:`piezometric_extension` on the graph of ``hidden`` and ``conductance``."""
    return piezometric_extension(HiddenGraph(hidden, conductance), p, rho, gx, solver)
