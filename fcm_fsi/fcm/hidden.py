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

from .hidden_graph import (
    GRAPH_REACH,
    HiddenGraph,
    LaplaceSolver,
    chain_conductance,
    piezometric_extension,
    radius_conductance,
    symmetric_graph,
)
from .levelset import Shapes
from .levelset_reference import signed_distance_reference
from .locate import NearPairs, PointLocator
from .surface_samples import surface_samples

#: ``cut_owner`` of a cell that Γ does not cut (any body's sample in it may be wetted)
NOT_CUT = -9


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


#: a contact link between hidden samples of two bodies stays while they are closer than this ×
#: the reach that made it
LINK_HYSTERESIS = 1.1
#: the candidates for contact links are searched to this × the reach beyond the links' range
CONTACT_MARGIN = 0.5


class HiddenSurface:
    """The samples of the surface of every body that has level-set primitives (a body without
    any, such as a foundation below the ground, is not in the fluid) (:func:`body_samples`) and
    the load of the static pressure on them, the hidden ones' by
    :func:`~.hidden_graph.piezometric_extension`. ``share`` and ``pressure`` are P1
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
        self._kept = None                            # the last classification (_Classified)
        # candidate pairs of samples of different bodies for the links, searched again for a body
        # only when it has moved CONTACT_MARGIN / 2 reaches
        reach = GRAPH_REACH * self.spacing
        self.near = NearPairs(self.body, LINK_HYSTERESIS * reach, CONTACT_MARGIN * reach)

    def forget(self) -> None:
        """The cut changed (a rebuild): the next :meth:`load` locates and classifies the samples
        anew, even at the same poses."""
        self._kept = None

    def _locate(self, share, points: np.ndarray, slots: np.ndarray, body: np.ndarray, cut_owner: np.ndarray,
                solid: np.ndarray, filled: np.ndarray, bridged: np.ndarray | None = None):
        """``points`` (n, 3) (their slots in :attr:`locator`: the samples' indices, n_samples +
        index for their probe points) located in this rank's owned cells (a :class:`_Located`),
        the P1 ``share`` χ at them (NaN outside the mesh) and per point whether the fluid does not
        reach it: outside the mesh, every cell containing it solid (``solid``, local cells: no
        vertex in the fluid; for the points flagged ``bridged``, near a clump's crease, only
        solid cells with a vertex the fill sets, ``filled``), or a cell containing it cut and
        giving its load to others than the point's ``body`` (``cut_owner`` (local cells, 2):
        owner and second owner of each cut cell's load, NOT_CUT for the cells Γ does not cut).
        Owned cells only, summed over the ranks: the same on any partition."""
        n = len(points)
        point, cell = self.locator.locate(slots, points)
        foreign = (cut_owner[cell, 0] != NOT_CUT) & (cut_owner[cell, 0] != body[point]) \
            & (cut_owner[cell, 1] != body[point])
        local = np.zeros((6, n))                      # χ, hits, counts: one reduction
        found, first = np.unique(point, return_index=True)
        held, cells = points[found], cell[first]
        local[0, found] = self.locator.p1.values((share,), held, cells)[0]
        local[1, found] = 1.0
        local[2] = np.bincount(point, minlength=n)                            # containing cells
        local[3] = np.bincount(point[solid[cell]], minlength=n)               # of them solid
        local[4] = np.bincount(point[foreign], minlength=n)                   # of them another body's
        local[5] = np.bincount(point[solid[cell] & filled[cell]], minlength=n)   # solid, the fill's
        self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        at = _Located(found, held, cells, local[1])
        counts = local[2:]
        bridged = np.zeros(n, bool) if bridged is None else bridged
        all_solid = (counts[1] == counts[0]) & (~bridged | (counts[3] == counts[0]))
        unreached = (counts[0] == 0) | all_solid | (counts[2] > 0)
        return at, at.average(local[0]), unreached

    def _values(self, functions, at: _Located) -> np.ndarray:
        """(len(functions), n) values of the P1 ``functions`` at the points ``at`` holds, on
        every rank (the ranks' owned cells summed and averaged), NaN outside the mesh."""
        local = np.zeros((len(functions), len(at.hit)))
        local[:, at.found] = self.locator.p1.values(functions, at.points, at.cells)
        self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
        return at.average(local)

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
        take their own, the hidden ones :func:`~.hidden_graph.piezometric_extension` from the
        wetted ones around them (which samples are hidden: :meth:`_classify`). ``density`` is a P1 function
        [kg/m³] or a number, ``gravity`` (dim,) [m/s²], ``depth`` [m] the 2D span (1 in 3D).
        The classification and the graph are kept while the poses (``pos``, ``rot``) and the
        cut stay (the later passes of an implicit step): only the values are read again.
        Collective; the same on all ranks."""
        force, torque = np.zeros((self.nb, 3)), np.zeros((self.nb, 3))
        self.hidden_measure[:] = 0.0
        self.unreached = 0
        if self.body.size == 0:
            return force, torque
        g = np.asarray(gravity, float)[: self.dim]
        k = self._kept
        if k is None or not (np.array_equal(k.pos, pos) and np.array_equal(k.rot, rot)):
            k = self._kept = self._classify(share, g, cut_owner, solid, filled, pos, rot)
        fns = (pressure,) if np.isscalar(density) else (pressure, density)
        vals = self._values(fns, k.at)
        rho = np.full(len(k.xw), float(density)) if np.isscalar(density) else np.nan_to_num(vals[1])
        p = np.nan_to_num(vals[0])
        if k.probe_at is not None:
            # a hidden sample that faces open fluid takes the static pressure a probe distance out,
            # moved hydrostatically to it
            pv = self._values(fns, k.probe_at)
            facing = k.facing
            idx = k.cand[facing]
            rho_probe = np.full(len(k.cand), float(density)) if np.isscalar(density) else np.nan_to_num(pv[1])
            p[idx] = pv[0][facing] + rho_probe[facing] * (k.gx[idx] - k.probe[facing, : self.dim] @ g)
            rho[idx] = rho_probe[facing]
        ph = piezometric_extension(k.graph, p, rho, k.gx, self.solver)
        reached = np.isfinite(ph)
        hidden = k.hidden
        self.unreached = int(np.unique(self.body[hidden & ~reached]).size)
        f = -(np.where(reached, ph, 0.0) * self.weight * depth)[:, None] * k.nw     # −p n dA per sample
        m = np.cross(k.xw - pos[self.body, :3], f)
        for i in range(3):
            force[:, i] = np.bincount(self.body, weights=f[:, i], minlength=self.nb)
            torque[:, i] = np.bincount(self.body, weights=m[:, i], minlength=self.nb)
        self.hidden_measure[:] = np.bincount(self.body[hidden], weights=self.weight[hidden], minlength=self.nb)
        self.last = {"x": k.xw, "n": k.nw, "w": self.weight, "body": self.body, "hidden": hidden,
                     "p": vals[0], "p_hidden": ph}
        return force, torque

    def _classify(self, share, g: np.ndarray, cut_owner: np.ndarray, solid: np.ndarray, filled: np.ndarray,
                  pos: np.ndarray, rot: np.ndarray) -> _Classified:
        """The samples at the poses ``pos``, ``rot``: located, which are hidden, and the graph of
        the hidden ones. Hidden: where the P1 ``share`` χ is 1 (the fill or a neighbour sets the
        level set in a cut cell at it), or where the fluid does not reach at all (outside the
        mesh, in solid cells only, or in a cut cell whose load goes to another body:
        :meth:`_locate`) — unless the sample faces open fluid: the point ``probe`` [m] out along
        its normal lies in the mesh, in a cell with fluid, not in another body's cut, not the
        fill's (the side of a wall inside the fill's corner at the floor, whose water is the open
        water beside it). Collective."""
        R = rot[self.body]
        xw = pos[self.body, :3] + np.einsum("nij,nj->ni", R, self.x_body)
        nw = np.einsum("nij,nj->ni", R, self.n_body)
        if self.dim == 2:
            xw[:, 2], nw[:, 2] = 0.0, 0.0
        ns = len(xw)
        at, chi, whole = self._locate(share, xw, np.arange(ns), self.body, cut_owner, solid, filled, self.bridged)
        hidden = whole | (np.nan_to_num(chi) >= 1.0 - 1e-9)
        k = _Classified(pos.copy(), rot.copy(), xw, nw, xw[:, : self.dim] @ g, at)
        k.cand = np.flatnonzero(hidden)
        if self.probe > 0 and k.cand.size:
            k.probe = xw[k.cand] + self.probe * nw[k.cand]
            k.probe_at, chi_probe, closed = self._locate(share, k.probe, ns + k.cand, self.body[k.cand], cut_owner,
                                                         solid, filled)
            k.facing = ~closed & (k.probe_at.hit > 0) & (np.nan_to_num(chi_probe) < 1.0 - 1e-9)
            hidden[k.cand[k.facing]] = False
        k.hidden = hidden
        k.graph = HiddenGraph(hidden, self.conductance + self._contact_conductance(xw, hidden))
        return k


class _Located:
    """Points located in this rank's owned cells: ``found`` the indices of the points it holds,
    ``points`` those points, ``cells`` one owned cell of each; ``hit`` (n,) how many ranks hold
    each point (0: outside the mesh)."""

    def __init__(self, found: np.ndarray, points: np.ndarray, cells: np.ndarray, hit: np.ndarray) -> None:
        self.found, self.points, self.cells, self.hit = found, points, cells, hit

    def average(self, summed: np.ndarray) -> np.ndarray:
        """Values summed over the ranks, divided by the ranks that hold each point; NaN outside the mesh."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.hit > 0, summed / np.maximum(self.hit, 1.0), np.nan)


class _Classified:
    """What the poses and the cut fix of a :meth:`HiddenSurface.load` (:meth:`HiddenSurface._classify`):
    the poses, the samples' world positions ``xw``, normals ``nw`` and g·x ``gx``, where they
    are (``at``), the hidden candidates ``cand`` with their probe points (``probe``,
    ``probe_at``) and which face open fluid (``facing``), the hidden flags and their graph."""

    def __init__(self, pos, rot, xw, nw, gx, at: _Located) -> None:
        self.pos, self.rot, self.xw, self.nw, self.gx, self.at = pos, rot, xw, nw, gx, at
        self.cand = np.zeros(0, np.int64)
        self.probe = np.zeros((0, 3))
        self.probe_at = None
        self.facing = np.zeros(0, bool)
        self.hidden = np.zeros(len(xw), bool)
        self.graph = None
