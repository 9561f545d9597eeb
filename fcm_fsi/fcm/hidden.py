"""Pressure on the parts of a body's surface that the fluid does not reach
(``coupling.hidden_pressure``; 2D and 3D fluids).

Where a block lies on the floor, on a stopper or on another block, the gap fill
(fcm/levelset.py) makes the thin gap between them solid: the fluid's cut surface runs
around the fill, and the block's own surface inside it carries no pressure. A block lying
on the floor in still water then gets the water's weight on its top and nothing from
below — a downward load instead of Archimedes' lift (docs/coupling.md). Real contacts are
rough and their water connects to the water around them; the pressure in the gap goes from
one mouth's to the other's, as the uplift in a joint of masonry or under a caisson.

Each moving body's surface is sampled in its body frame with cells no longer (2D) or no
wider (3D) than ``spacing``: midpoints, outward normals and lengths or areas
(:func:`surface_samples`). A body made of several primitives (a clump of spheres) keeps the
samples of each primitive that lie outside the others.

The split of the load. The body's load is the flow's part on the cut surface Γ (the fluid's
pressure less the static one, with the viscous traction) plus the static pressure on the
samples of its true surface: −Σ P n dA over all samples (× ``coupling.depth`` in 2D). The
coupling takes the static pressure's load on Γ off the body (``CutDomain.pressure_load``) and
adds this one. The static part therefore does not depend on where Γ runs (through the fill,
across a clump's notch, chamfering a box's edges): the true surface carries it once.

Which part is hidden. The fluid does not reach a sample outside the mesh, in cells that are
all solid (no vertex in the fluid: under the fill or inside another body), in a cut cell
whose load goes to another body, or where the P1 ``share`` χ is 1 (the coupling sets it to 1 at
every vertex of a cut cell in which the fill or a neighbour sets the level set). Near a clump's
crease (within a cell of another of its primitives) the body's own P1 level set bridges the
notch: solid cells there hide a sample only where the fill sets a vertex of each of them (a
notch under the fill, at the floor). A sample that faces open fluid is not hidden: the point a
probe distance out along its normal lies in the mesh, in a cell with fluid, outside another
body's cut and the fill (the side of a wall inside the fill's corner at the floor); it takes
the static pressure at that point, moved hydrostatically to it.

What pressure on the hidden ones. The piezometric pressure p − ρ g·x and the density ρ of the
steady flow through a thin gap of uniform opening from the samples around them: the Reynolds
equation of such a gap is Laplace's equation on the surface, solved here on a graph of the
samples (:func:`interpolate_hidden`). On a closed curve (a 2D body of one primitive) the graph
is the chain of samples and the solution is linear in arc length between the two mouths; on a
surface, or a 2D clump, it links samples closer than :data:`GRAPH_REACH` spacings with
conductance 1/distance². Water at rest has one piezometric pressure per fluid, which any such
interpolation keeps exactly, so a body at rest gets Archimedes' lift on any path round a
corner. Hidden samples of different bodies that touch are linked too: their joint holds one
film of water, and the lower block of a stack, hidden all round, reaches the mouths of the
blocks above it. A hidden patch with no wetted sample around it (a body hidden all round) gets
no pressure (counted in ``unreached``).

The samples' load goes to the body only: the reaction of its hidden part is the floor's or the
other body's, and the fluid's momentum does not contain it.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve
from scipy.spatial import cKDTree

from .levelset import Shapes
from .levelset_reference import signed_distance_reference
from .locate import NearPairs, PointLocator
from .surface_samples import surface_samples

#: ``cut_owner`` of a cell that Γ does not cut (any body's sample in it may be wetted)
NOT_CUT = -9
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


def body_samples(shapes: Shapes, body: int, spacing: float,
                 dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, sp.csr_matrix]:
    """The surface of body ``body`` (the union of its primitives) in its body frame: points,
    outward normals, lengths or areas (:func:`surface_samples`) and the conductance of its
    sample graph (one 2D primitive: :func:`chain_conductance`; else
    :func:`radius_conductance`). The samples of one primitive are clipped to the outside of the
    body's other primitives (a clump's overlaps, faces in contact: :func:`clipped_samples`)."""
    mine = np.flatnonzero(shapes.body == body)
    if mine.size == 0:
        raise ValueError(f"body {body} has no level-set primitive")
    parts = [surface_samples(int(shapes.kind[k]), shapes.half[k], shapes.offset[k], shapes.rot[k], spacing, dim,
                             shapes.triangles[k]) for k in mine]
    if mine.size == 1:
        x, n, w = parts[0]
        return x, n, w, (chain_conductance(w) if dim == 2 else radius_conductance(x, spacing))
    frame_pos, frame_quat = np.zeros((body + 1, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (body + 1, 1))
    kept = []
    for k, (x, n, w) in zip(mine, parts):
        others = mine[mine != k]
        sub = shapes.take(others)

        def distance(points, sub=sub):
            return signed_distance_reference(points, sub, frame_pos, frame_quat, np.inf)[0]
        x, w = clipped_samples(x, n, w, distance, 1e-6 * spacing, dim)
        out = w > 0
        kept.append((x[out], n[out], w[out]))
    x, n, w = (np.concatenate([p[i] for p in kept]) for i in range(3))
    return x, n, w, radius_conductance(x, spacing)


#: sub-points along each side of a sample's patch that measure the part of a patch straddling
#: another primitive of its body: a clump's surface then ends at the crease to 1/16 of a
#: sample, not to a whole one (the static pressure there, unbalanced, is a side load)
CLIP_SUBPOINTS = 16


def patch_points(x: np.ndarray, n: np.ndarray, w: np.ndarray, dim: int) -> np.ndarray:
    """(len(x), m, 3) points spread over each sample's patch: the segment of length ``w`` along
    the tangent in 2D, the square of area ``w`` in the tangent plane in 3D, on a grid of
    :data:`CLIP_SUBPOINTS` per side (cell midpoints)."""
    k = CLIP_SUBPOINTS
    s = (np.arange(k) + 0.5) / k - 0.5
    if dim == 2:
        t = np.column_stack([-n[:, 1], n[:, 0], np.zeros(len(n))])
        return x[:, None, :] + (w[:, None, None] * s[None, :, None]) * t[:, None, :]
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(n, t1)
    a, b = (g.ravel() for g in np.meshgrid(s, s, indexing="ij"))
    side = np.sqrt(w)[:, None, None]
    return x[:, None, :] + side * (a[None, :, None] * t1[:, None, :] + b[None, :, None] * t2[:, None, :])


def clipped_samples(x: np.ndarray, n: np.ndarray, w: np.ndarray, distance, margin: float,
                    dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Samples (points ``x``, normals ``n``, lengths or areas ``w``) clipped to where
    ``distance(points)`` (the signed distance to the other primitives [m]) exceeds ``margin``:
    a sample whose patch (:func:`patch_points`) lies partly beyond keeps that part of its
    weight, at the centroid of that part; a sample wholly within gets weight 0."""
    x, w = x.copy(), w.copy()
    d = distance(x)
    extent = 0.5 * w if dim == 2 else np.sqrt(0.5 * w)        # from the midpoint to the patch's farthest point
    w[d <= margin - extent] = 0.0
    near = np.flatnonzero(np.abs(d - margin) < extent)
    if near.size:
        pts = patch_points(x[near], n[near], w[near], dim)
        flags = distance(pts.reshape(-1, 3)).reshape(pts.shape[:2]) > margin
        frac = flags.mean(axis=1)
        w[near] *= frac
        some = frac > 0
        x[near[some]] = (pts[some] * flags[some][:, :, None]).sum(axis=1) / flags[some].sum(axis=1)[:, None]
    return x, w


def crease_distance(shapes: Shapes, body: int, x: np.ndarray) -> np.ndarray:
    """Distance [m] of surface samples ``x`` (body frame) of body ``body`` to its other
    primitives' surfaces, the smallest over them (∞ for a body of one primitive): near a
    clump's crease, where the P1 level set bridges the notch between its primitives."""
    mine = np.flatnonzero(shapes.body == body)
    if mine.size < 2:
        return np.full(len(x), np.inf)
    frame_pos, frame_quat = np.zeros((body + 1, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (body + 1, 1))
    out = np.full(len(x), np.inf)
    for k in mine:
        sub = shapes.take([k])
        d, _ = signed_distance_reference(x, sub, frame_pos, frame_quat, np.inf)
        on_k = np.abs(d) <= 1e-9 * max(1.0, float(np.abs(x).max(initial=1.0)))
        out = np.where(on_k, out, np.minimum(out, np.abs(d)))
    return out


def interpolate_hidden(hidden: np.ndarray, values: np.ndarray, conductance: sp.spmatrix,
                       solver: LaplaceSolver | None = None) -> np.ndarray:
    """``values`` (n,) or (n, k) at every sample: wetted samples keep theirs, hidden ones get
    the harmonic extension of the wetted values over the sample graph of ``conductance``
    (n, n) (Σ_j c_ij (v_j − v_i) = 0 at each hidden sample), solved by ``solver`` (a fresh
    :class:`LaplaceSolver` by default). Hidden samples with no path to a wetted one: NaN."""
    out = np.array(values, dtype=float, copy=True)
    H, W = np.flatnonzero(hidden), np.flatnonzero(~np.asarray(hidden, bool))
    if H.size == 0:
        return out
    C = sp.csr_matrix(conductance)
    A, B = C[H][:, H], C[H][:, W]
    to_wet = np.asarray(B.sum(axis=1)).ravel()
    ncomp, label = connected_components(A, directed=False)
    reached = (np.bincount(label, weights=to_wet, minlength=ncomp) > 0)[label]
    out[H[~reached]] = np.nan
    if reached.any():
        A, B = A[reached][:, reached], B[reached]
        L = sp.diags(np.asarray(A.sum(axis=1)).ravel() + to_wet[reached]) - A
        rhs = B @ out[W]
        solver = LaplaceSolver() if solver is None else solver
        out[H[reached]] = solver.solve(L.tocsr(), rhs.reshape(len(rhs), -1), H[reached]).reshape(rhs.shape)
    return out


#: a contact link between hidden samples of two bodies stays while they are closer than this ×
#: the reach that made it
LINK_HYSTERESIS = 1.1
#: the candidates for contact links are searched to this × the reach beyond the links' range
CONTACT_MARGIN = 0.5

#: graph Laplacians with more unknowns than this are solved by preconditioned CG, smaller ones by
#: sparse LU (whose fill-in makes the 10⁵ hidden samples of a building's joints slow)
DIRECT_LIMIT = 5000
#: the CG preconditioner of the larger graph Laplacians, and the tolerance relative to ‖rhs‖ (on
#: the tsunami building's 73,000 joint samples the load moves by 3e-9 of itself from 1e-10 to this,
#: at 2/3 of the iterations)
GRAPH_PC = "icc"
GRAPH_RTOL = 1e-8


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
    little."""

    def __init__(self, comm=None) -> None:
        self.comm = comm
        self._pattern = None         # (indptr, indices) of the matrix the preconditioner was built for
        self._ksp = self._A = None
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
        from petsc4py import PETSc
        L = sp.csr_matrix(L)
        L.sort_indices()
        same = self._pattern is not None and np.array_equal(self._pattern[0], L.indptr) \
            and np.array_equal(self._pattern[1], L.indices)
        if same:
            self._A.setValuesCSR(L.indptr.astype(PETSc.IntType), L.indices.astype(PETSc.IntType), L.data)
            self._A.assemble()
        else:
            self._free_operator()
            self._A = PETSc.Mat().createAIJ(size=L.shape, csr=(L.indptr.astype(PETSc.IntType),
                                                               L.indices.astype(PETSc.IntType), L.data),
                                            comm=PETSc.COMM_SELF)
            self._ksp = PETSc.KSP().create(PETSc.COMM_SELF)
            self._ksp.setType("cg")
            self._ksp.getPC().setType(GRAPH_PC)
            self._ksp.setTolerances(rtol=GRAPH_RTOL, atol=0.0, max_it=2000)
            self._pattern = (L.indptr.copy(), L.indices.copy())
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

    def _free_operator(self) -> None:
        for obj in (self._ksp, self._A):
            if obj is not None:
                obj.destroy()
        self._ksp = self._A = self._pattern = None

    def destroy(self) -> None:
        self._free_operator()
        self._last = self._last_ids = None


def hidden_pressure(hidden: np.ndarray, p: np.ndarray, rho: np.ndarray, gx: np.ndarray,
                    conductance: sp.spmatrix, solver: LaplaceSolver | None = None) -> np.ndarray:
    """Pressure [Pa] at the samples: wetted ones keep ``p``; on the hidden ones the
    piezometric pressure p − ρ g·x and the density ρ are extended from the mouths
    (:func:`interpolate_hidden`) and p = (p − ρ g·x) + ρ g·x at the sample (``gx`` = g·x
    [m²/s²] per sample). Exact for water at rest whatever the path."""
    both = interpolate_hidden(hidden, np.column_stack([p - rho * gx, rho]), conductance, solver)
    return both[:, 0] + both[:, 1] * gx


class HiddenSurface:
    """The samples of the surface of every body that has level-set primitives (a body without
    any, such as a foundation below the ground, is not in the fluid) (:func:`body_samples`) and
    the load of :func:`hidden_pressure` on the hidden ones. ``share`` and ``pressure`` are P1
    functions on ``mesh``; 2D meshes sample each body's section z = 0."""

    def __init__(self, mesh, shapes: Shapes, nbodies: int, spacing: float, bridge: float = 0.0,
                 probe: float = 0.0) -> None:
        self.mesh, self.comm, self.nb = mesh, mesh.comm, int(nbodies)
        self.dim = mesh.topology.dim
        x, n, w, graphs, body = [], [], [], [], []
        for b in np.unique(shapes.body[shapes.body >= 0]):
            xb, nb_, wb, cb = body_samples(shapes, int(b), spacing, self.dim)
            x.append(xb), n.append(nb_), w.append(wb), graphs.append(cb)
            body.append(np.full(len(wb), int(b)))
        self.x_body = np.concatenate(x) if x else np.zeros((0, 3))      # [m] body frames
        self.n_body = np.concatenate(n) if n else np.zeros((0, 3))
        self.weight = np.concatenate(w) if w else np.zeros(0)           # [m] 2D, [m²] 3D
        self.body = np.concatenate(body) if body else np.zeros(0, np.int64)
        # samples within ``bridge`` [m] of a clump's crease: the body's own P1 level set bridges
        # the notch there, and its cut surface Γ carries the notch's load, so solid cells
        # round them do not hide them (a hidden notch sample would count that load twice)
        crease = [crease_distance(shapes, int(b), xb) for b, xb in zip(np.unique(self.body), x)]
        self.bridged = np.concatenate(crease) < bridge if crease else np.zeros(0, bool)
        self.conductance = sp.block_diag(graphs, format="csr") if graphs else sp.csr_matrix((0, 0))
        self.spacing = float(spacing)
        self.locator = PointLocator(mesh, 2 * len(self.weight))   # the samples, then their probe points
        self.solver = LaplaceSolver(self.comm)       # the hidden samples' graph, kept between steps
        self.probe = float(probe)                    # [m] how far out a hidden sample looks for open fluid
        self.hidden_measure = np.zeros(self.nb)      # hidden length [m] (2D) or area [m²] (3D) per body, last call
        self.unreached = 0                           # bodies with hidden samples no mouth reaches, last call
        self.last = {}                               # the samples of the last call, for plots
        self._links = np.zeros(0, np.int64)          # contact links (i n + j, i < j) of the last call
        # candidate pairs of samples of different bodies for the links, searched again for a body
        # only when it has moved CONTACT_MARGIN / 2 reaches
        reach = GRAPH_REACH * self.spacing
        self.near = NearPairs(self.body, LINK_HYSTERESIS * reach, CONTACT_MARGIN * reach)

    def _values(self, functions, points: np.ndarray, slots: np.ndarray, body: np.ndarray, cut_owner: np.ndarray,
                solid: np.ndarray, filled: np.ndarray, bridged: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(len(functions), n) values at ``points`` (n, 3) (their slots in :attr:`locator`:
        the samples' indices, n_samples + index for their probe points) on every rank, NaN outside the
        mesh, and per point whether the fluid does not reach it: outside the mesh, every cell
        containing it solid (``solid``, local cells: no vertex in the fluid; for the points
        flagged ``bridged``, near a clump's crease, only solid cells with a vertex the fill sets,
        ``filled``), or a cell containing it cut and giving its load to others than the point's
        ``body``
        (``cut_owner`` (local cells, 2): owner and second owner of each cut cell's load,
        NOT_CUT for the cells Γ does not cut). Owned cells only, summed over the ranks: the
        same on any partition."""
        n = len(points)
        point, cell = self.locator.locate(slots, points)
        foreign = (cut_owner[cell, 0] != NOT_CUT) & (cut_owner[cell, 0] != body[point]) \
            & (cut_owner[cell, 1] != body[point])
        counts = np.zeros((4, n))
        counts[0] = np.bincount(point, minlength=n)                      # containing cells
        counts[1] = np.bincount(point[solid[cell]], minlength=n)         # of them solid
        counts[2] = np.bincount(point[foreign], minlength=n)             # of them another body's
        counts[3] = np.bincount(point[solid[cell] & filled[cell]], minlength=n)   # solid, the fill's
        found, first = np.unique(point, return_index=True)
        local = np.zeros((len(functions) + 1 + len(counts), n))      # values, hits, counts: one reduction
        local[: len(functions), found] = self.locator.p1.values(functions, points[found], cell[first])
        local[len(functions), found] = 1.0
        local[len(functions) + 1:] = counts
        self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        hit, counts = local[len(functions)], local[len(functions) + 1:]
        local = local[: len(functions)]
        bridged = np.zeros(n, bool) if bridged is None else bridged
        all_solid = (counts[1] == counts[0]) & (~bridged | (counts[3] == counts[0]))
        unreached = (counts[0] == 0) | all_solid | (counts[2] > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(hit > 0, local / np.maximum(hit, 1.0), np.nan), unreached

    def _contact_conductance(self, xw: np.ndarray, hidden: np.ndarray) -> sp.csr_matrix:
        """Links between hidden samples of different bodies closer than :data:`GRAPH_REACH`
        spacings (world positions ``xw``): where blocks touch, the water of their joint is one
        film, and a block hidden all round (the lower block of a stack) reaches the mouths of
        the others. Conductance 1/max(distance, spacing/2)² (coincident faces: the same
        pressure on both). A link of the last call stays up to :data:`LINK_HYSTERESIS` × the
        reach, so that samples at the reach of a structure that only trembles do not change
        the graph's links from step to step (its preconditioner is then kept)."""
        n = len(xw)
        reach = GRAPH_REACH * self.spacing
        i, j, d2 = self.near.pairs(xw, hidden)
        key = i * n + j
        linked = np.zeros(len(key), bool)
        if self._links.size:
            at = np.minimum(np.searchsorted(self._links, key), self._links.size - 1)
            linked = self._links[at] == key
        keep = (d2 <= reach * reach) | linked
        i, j, d2 = i[keep], j[keep], d2[keep]
        self._links = np.sort(key[keep])
        c = 1.0 / np.maximum(d2, 0.25 * self.spacing ** 2)
        return symmetric_graph(i, j, c, n)

    def load(self, share, pressure, density, gravity: np.ndarray, cut_owner: np.ndarray, solid: np.ndarray,
             filled: np.ndarray, pos: np.ndarray, rot: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray]:
        """Force (nb, 3) [N] and torque about each body's centre (nb, 3) [N m] of ``pressure``
        (the static pressure, a P1 function) on each body's whole surface: the wetted samples
        take their own, the hidden ones :func:`hidden_pressure` from the wetted ones around
        them. Hidden: where the P1 ``share`` χ is 1 (the fill or a neighbour sets the level set
        in a cut cell at it), or where the fluid does not reach at all (outside the mesh, in
        solid cells only, or in a cut cell whose load goes to another body: :meth:`_values`) —
        unless the sample faces open fluid: the point ``probe`` [m] out along its normal lies
        in the mesh, in a cell with fluid, not in another body's cut (the side of a wall inside
        the fill's corner at the floor, whose water is the open water beside it). ``density``
        is a P1 function [kg/m³] or a number, ``gravity`` (dim,) [m/s²], ``depth`` [m] the 2D
        span (1 in 3D). Collective; the same on all ranks."""
        force, torque = np.zeros((self.nb, 3)), np.zeros((self.nb, 3))
        self.hidden_measure[:] = 0.0
        self.unreached = 0
        if self.body.size == 0:
            return force, torque
        R = rot[self.body]
        xw = pos[self.body, :3] + np.einsum("nij,nj->ni", R, self.x_body)
        nw = np.einsum("nij,nj->ni", R, self.n_body)
        if self.dim == 2:
            xw[:, 2], nw[:, 2] = 0.0, 0.0
        fns = (share, pressure) + (() if np.isscalar(density) else (density,))
        ns = len(xw)
        vals, whole = self._values(fns, xw, np.arange(ns), self.body, cut_owner, solid, filled, self.bridged)
        rho = np.full(len(xw), float(density)) if np.isscalar(density) else np.nan_to_num(vals[2])
        hidden = whole | (np.nan_to_num(vals[0]) >= 1.0 - 1e-9)
        g = np.asarray(gravity, float)[: self.dim]
        gx = xw[:, : self.dim] @ g
        p = np.nan_to_num(vals[1])
        cand = np.flatnonzero(hidden)
        if self.probe > 0 and cand.size:
            # a hidden sample that faces open fluid (the point a probe distance out along its
            # normal is in the mesh, in a cell with fluid, not in another body's cut, not the
            # fill's: the side of a wall inside the fill's corner at the floor) is wetted, with
            # the static pressure there moved hydrostatically to it
            probe = xw[cand] + self.probe * nw[cand]
            pv, closed = self._values(fns, probe, ns + cand, self.body[cand], cut_owner, solid, filled)
            facing = ~closed & np.isfinite(pv[1]) & (np.nan_to_num(pv[0]) < 1.0 - 1e-9)
            idx = cand[facing]
            rho_probe = np.full(len(cand), float(density)) if np.isscalar(density) else np.nan_to_num(pv[2])
            p[idx] = pv[1][facing] + rho_probe[facing] * (gx[idx] - probe[facing, : self.dim] @ g)
            rho[idx] = rho_probe[facing]
            hidden[idx] = False
        graph = self.conductance + self._contact_conductance(xw, hidden)
        ph = hidden_pressure(hidden, p, rho, gx, graph, self.solver)
        reached = np.isfinite(ph)
        self.unreached = int(np.unique(self.body[hidden & ~reached]).size)
        f = -(np.where(reached, ph, 0.0) * self.weight * depth)[:, None] * nw     # −p n dA per sample
        m = np.cross(xw - pos[self.body, :3], f)
        for k in range(3):
            force[:, k] = np.bincount(self.body, weights=f[:, k], minlength=self.nb)
            torque[:, k] = np.bincount(self.body, weights=m[:, k], minlength=self.nb)
        self.hidden_measure[:] = np.bincount(self.body[hidden], weights=self.weight[hidden], minlength=self.nb)
        self.last = {"x": xw, "n": nw, "w": self.weight, "body": self.body, "hidden": hidden,
                     "p": vals[1], "p_hidden": ph}
        return force, torque
