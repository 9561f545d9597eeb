"""Bonded structures from CAD files (``dem.blocks[].fill: bonded_grid``): the solid S bounded by a
closed triangle surface, cut by a cubic grid of cell size g into rigid pieces bonded by the
cohesive law on the faces they share.

The grid starts at the lower corner of the surface's bounding box (the file's frame, scaled), so
a box read from a file and cut by a g that divides its edges gives the boxes of a bonded box
structure. A piece is S ∩ U, U one grid cell or a few joined ones, and is described exactly by
its signed distance max(d_S, d_U): d_S the surface's (winding-number sign,
fcm_fsi/geometry/surface_distance.py), d_U the exact distance to the union of the cells' boxes
(outside: the least box distance; inside: minus the distance to U's outer faces). From it:

- its surface: the triangles of S clipped to its cells (Sutherland–Hodgman; a triangle lying in
  a grid plane belongs to the cell its normal points out of) and, on each outer face of U, the
  cut face S ∩ face: a triangulated lattice of spacing ≤ ``cap_spacing`` whose triangles are
  kept where S lies on both sides of the face (a staircase of that spacing along the cut's
  edge). Mass, centre and inertia follow from this surface by the divergence theorem
  (geometry/surface.py), exact for the cut faces a lattice covers and within the lattice's
  resolution at the cut's edge;
- its contact spheres: the nodes of the block's sphere lattice at depth r ≤ d < r + a below its
  surface (as a whole block's, dem/mesh_block.py), so the spheres of neighbouring pieces just
  touch across their shared face, as a bonded box structure's do;
- the fluid's view: max(d_S, d_U) on a grid of node spacing ``sdf_spacing`` (fcm/shapes.py, kind
  MESH) and the piece's surface triangles as its surface samples.

A piece in which no contact sphere fits (a sliver at the solid's edge) joins the neighbour it
shares the largest face with, until every piece has spheres. Two pieces are bonded on every
cell face they share, with the cohesive law's Gauss points on that face (``points_per_edge``²),
on a 4 × 4 subdivision of it where S covers the face only partly, keeping the points inside S.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..config.dem import BlockConfig
from ..config.loader import ConfigError
from ..geometry.surface import ClosedSurface, MassProperties, mass_properties
from ..geometry.surface_distance import DistanceGrid, signed_distance
from ..io.logging import get_logger
from .bodies import BlockTemplate
from .cohesive import face_points
from .mesh_block import block_surface, lattice_axes

log = get_logger("dem")

_PARTIAL_SPLIT = 4       # sub-rectangles per edge of a partly covered bond face
_EMPTY = "empty"         # a cell the solid only touches


@dataclass(frozen=True)
class GridPiece:
    """One piece: its ``cells`` (k, 3) grid indices, surface triangles ``corners`` (nt, 3, 3)
    and ``properties`` in the file's frame [m], and its ``template`` (principal frame)."""

    cells: np.ndarray
    corners: np.ndarray
    properties: MassProperties
    template: BlockTemplate


@dataclass(frozen=True)
class GridBond:
    """Pieces ``a`` < ``b`` joined on the grid face of ``normal`` (unit, from a to b) through
    the cohesive points ``points`` (m, 3) [m] of ``areas`` (m,) [m²], file frame."""

    a: int
    b: int
    normal: np.ndarray
    points: np.ndarray
    areas: np.ndarray


@dataclass(frozen=True)
class GridFill:
    """The pieces and bonds of a block of fill bonded_grid, and the grid: ``origin`` (3,) [m]
    and cell ``size`` [m]."""

    surface: ClosedSurface
    origin: np.ndarray
    size: float
    pieces: tuple[GridPiece, ...]
    bonds: tuple[GridBond, ...]

    def cell_box(self, cell) -> tuple[np.ndarray, np.ndarray]:
        lo = self.origin + self.size * np.asarray(cell, float)
        return lo, lo + self.size


def grid_fill(b: BlockConfig, density: float, points_per_edge: int, key: str = "dem.blocks[]") -> GridFill:
    """The pieces and bonds of block ``b`` (fill bonded_grid) of ``density`` [kg/m³] (cached)."""
    return _grid_fill(b, float(density), int(points_per_edge), key)


@lru_cache(maxsize=8)
def _grid_fill(b: BlockConfig, density: float, points_per_edge: int, key: str) -> GridFill:
    surface = block_surface(b, key)
    corners = np.ascontiguousarray(surface.corners)
    g = float(b.grid_size)
    lo, hi = surface.vertices.min(axis=0), surface.vertices.max(axis=0)
    n = np.maximum(np.ceil((hi - lo) / g * (1 - 1e-9)).astype(int), 1)
    spacing = 2.0 * b.radius if b.spacing is None else b.spacing
    cap = min(0.5 * b.radius, g / 8.0)
    cells = _occupied_cells(corners, lo, g, n)
    owner = {c: i for i, c in enumerate(cells)}                  # cell → piece (joined ones share)
    made: dict[tuple, GridPiece | str | None] = {}
    while True:
        members: dict[int, list] = {}
        for c, p in owner.items():
            members.setdefault(p, []).append(c)
        pieces, bare, empty = {}, [], []
        for p, cs in members.items():
            key_cells = tuple(sorted(cs))
            if key_cells not in made:
                made[key_cells] = _piece(corners, np.array(key_cells), lo, g, cap, density, b.radius, spacing)
            piece = made[key_cells]
            if isinstance(piece, str):
                empty.append(p)
            elif piece is None:
                bare.append(p)
            else:
                pieces[p] = piece
        for p in empty:                                          # cells the solid only touches
            for c in members[p]:
                del owner[c]
        if not bare:
            break
        p = bare[0]
        target = _largest_neighbour(members, owner, p, corners, lo, g)
        if target is None:
            raise ConfigError(f"key '{key}.radius' = {b.radius:g} m: no contact sphere fits in the piece of "
                              f"grid cells {members[p]} of {b.file!r} (grid_size {g:g} m), and it touches no "
                              "other piece: use smaller spheres or another grid_size")
        for c in members[p]:
            owner[c] = target
    ids = {p: i for i, p in enumerate(sorted(pieces))}
    owner = {c: ids[p] for c, p in owner.items()}
    bonds = _bonds(corners, owner, lo, g, points_per_edge)
    whole = mass_properties(surface, density).mass
    mass = sum(p.properties.mass for p in pieces.values())
    log.info("%s: %s cut on a %g m grid into %d pieces (%d joined slivers) with %d bonds; their mass %.6g kg, "
             "the polyhedron's %.6g kg (%+.2f %%)", key, b.file, g, len(pieces), len(owner) - len(pieces), len(bonds),
             mass, whole, 100.0 * (mass / whole - 1.0))
    return GridFill(surface, lo, g, tuple(pieces[p] for p in sorted(pieces)), tuple(bonds))


def _occupied_cells(corners: np.ndarray, lo: np.ndarray, g: float, n: np.ndarray) -> list[tuple]:
    """Grid cells holding part of the solid: those a triangle's bounding box meets or whose
    centre is inside (a cell cut by no triangle is wholly inside or wholly outside)."""
    ijk = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
    centres = lo + g * (ijk + 0.5)
    inside = signed_distance(np.ascontiguousarray(centres), corners) < 0
    tlo = np.floor((corners.min(axis=1) - lo) / g).astype(int).clip(0, n - 1)
    thi = np.floor((corners.max(axis=1) - lo) / g).astype(int).clip(0, n - 1)
    touched = np.zeros(n, bool)
    for a, c in zip(tlo, thi):
        touched[a[0]:c[0] + 1, a[1]:c[1] + 1, a[2]:c[2] + 1] = True
    keep = inside | touched[ijk[:, 0], ijk[:, 1], ijk[:, 2]]
    return [tuple(int(v) for v in c) for c in ijk[keep]]


# ------------------------------------------------------------------ one piece
def _piece(corners, cells, lo, g, cap, density, radius, spacing) -> GridPiece | str | None:
    """The piece S ∩ (the union of ``cells``); ``_EMPTY`` when it has no volume, None when no
    contact sphere fits in it."""
    boxes = lo + g * cells.astype(float)
    tri = np.concatenate([clip_to_box(corners, a, a + g) for a in boxes] + [np.zeros((0, 3, 3))])
    caps = [_cap(corners, face, cap) for face in outer_faces(cells, lo, g)]
    tri = np.concatenate([tri, *caps]) if caps else tri
    if len(tri) == 0:
        return _EMPTY
    centre = lo + g * (cells.mean(axis=0) + 0.5)
    props = mass_properties(ClosedSurface(tri.reshape(-1, 3) - centre, np.arange(3 * len(tri)).reshape(-1, 3)),
                            density)
    if props.volume <= 1e-9 * g ** 3:
        return _EMPTY
    props = MassProperties(props.volume, props.mass, props.centre + centre, props.inertia)
    spheres = _skin(corners, cells, lo, g, radius, spacing)
    if len(spheres) == 0:
        return None
    w, V = np.linalg.eigh(props.inertia)
    if np.linalg.det(V) < 0:
        V[:, 2] *= -1
    template = BlockTemplate(props.mass, w, (spheres - props.centre) @ V, np.full(len(spheres), float(radius)), V,
                             props.centre)
    return GridPiece(cells, tri, props, template)


def piece_distance(points: np.ndarray, corners: np.ndarray, cells: np.ndarray, lo, g: float,
                   surface_distance: np.ndarray | None = None) -> np.ndarray:
    """max(d_S, d_U) [m] at ``points`` (n, 3): the signed distance to the piece S ∩ U
    (``surface_distance``: d_S there when the caller has it)."""
    d_s = signed_distance(np.ascontiguousarray(points), corners) if surface_distance is None else surface_distance
    return np.maximum(d_s, union_distance(points, cells, lo, g))


def union_distance(points: np.ndarray, cells: np.ndarray, lo, g: float) -> np.ndarray:
    """Exact signed distance [m] to the union of grid ``cells`` (boxes lo + g·cell … + g):
    outside, the least box distance; inside, minus the distance to the union's outer faces."""
    p = np.asarray(points, float)
    best = np.full(len(p), np.inf)
    inside = np.zeros(len(p), bool)
    for c in cells:
        a = lo + g * np.asarray(c, float)
        q = np.abs(p - (a + 0.5 * g)) - 0.5 * g
        out = np.linalg.norm(np.maximum(q, 0.0), axis=1)
        inside |= np.all(q <= 0, axis=1)                    # closed boxes: a shared face is inside
        best = np.minimum(best, out)
    if inside.any():
        depth = np.full(int(inside.sum()), np.inf)
        pin = p[inside]
        for f in outer_faces(cells, lo, g):
            depth = np.minimum(depth, _rectangle_distance(pin, f))
        best[inside] = -depth
    return best


def outer_faces(cells: np.ndarray, lo, g: float) -> list[tuple]:
    """The faces of the union of ``cells`` not shared by two of them: (axis k, plane x_k [m],
    outward sign ±1, lower corner (3,) [m] of the face's square, its edge g [m])."""
    own = {tuple(int(v) for v in c) for c in cells}
    faces = []
    for c in sorted(own):
        for k in range(3):
            for s in (-1, 1):
                nb = list(c)
                nb[k] += s
                if tuple(nb) in own:
                    continue
                corner = lo + g * np.asarray(c, float)
                corner[k] += g if s > 0 else 0.0
                faces.append((k, corner[k], s, corner, g))
    return faces


def _rectangle_distance(p: np.ndarray, face) -> np.ndarray:
    """Distance [m] from ``p`` (n, 3) to the square ``face`` of :func:`outer_faces`."""
    k, plane, _, corner, g = face
    d = np.empty_like(p)
    for j in range(3):
        if j == k:
            d[:, j] = p[:, j] - plane
        else:
            d[:, j] = np.maximum(np.maximum(corner[j] - p[:, j], p[:, j] - corner[j] - g), 0.0)
    return np.linalg.norm(d, axis=1)


def clip_to_box(corners: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The parts (m, 3, 3) of triangles ``corners`` (nt, 3, 3) inside the box lo..hi, as fans of
    the clipped polygons (Sutherland–Hodgman). A triangle lying in a face plane of the box is
    kept when its normal points out of the box there."""
    tol = 1e-9 * max(1.0, float(np.abs(hi - lo).max()))
    near = np.all(corners.max(axis=1) >= lo - tol, axis=1) & np.all(corners.min(axis=1) <= hi + tol, axis=1)
    out = []
    for t in corners[near]:
        normal = np.cross(t[1] - t[0], t[2] - t[0])
        poly = [tuple(v) for v in t]
        for k in range(3):
            for bound, side in ((lo[k], 1.0), (hi[k], -1.0)):       # keep side·(x_k − bound) ≥ 0
                s = [side * (v[k] - bound) for v in poly]
                if all(abs(x) <= tol for x in s):                  # the polygon lies in this plane
                    if side * normal[k] >= 0:                       # its normal points into the box
                        poly = []
                    break
                poly = _clip(poly, s, tol)
                if not poly:
                    break
            if not poly:
                break
        for i in range(1, len(poly) - 1):
            out.append((poly[0], poly[i], poly[i + 1]))
    tri = np.array(out, float).reshape(-1, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return tri[area > tol * tol]


def _clip(poly: list, s: list, tol: float) -> list:
    """One Sutherland–Hodgman pass: the part of polygon ``poly`` where s ≥ 0."""
    out = []
    for i in range(len(poly)):
        p, q, sp, sq = poly[i], poly[(i + 1) % len(poly)], s[i], s[(i + 1) % len(poly)]
        if sp >= -tol:
            out.append(p)
        if (sp > tol and sq < -tol) or (sp < -tol and sq > tol):
            t = sp / (sp - sq)
            out.append(tuple(p[j] + t * (q[j] - p[j]) for j in range(3)))
    return out if len(out) >= 3 else []


def _cap(corners: np.ndarray, face, spacing: float) -> np.ndarray:
    """The cut face S ∩ ``face`` as triangles (m, 3, 3) facing out of the piece: a lattice of
    squares of side ≤ ``spacing`` over the face, each split in two, kept where S lies just
    inside and just outside the face at the square's centre (the whole face as two triangles
    where every square is kept)."""
    k, plane, sign, corner, g = face
    u, v = (k + 1) % 3, (k + 2) % 3
    m = max(1, int(np.ceil(g / spacing - 1e-9)))
    h = g / m
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    base = np.tile(corner, (m * m, 1))
    base[:, u] += h * i.reshape(-1)
    base[:, v] += h * j.reshape(-1)
    eu, ev = np.eye(3)[u], np.eye(3)[v]
    centre = base + 0.5 * h * (eu + ev)
    probe = 1e-6 * g
    keep = (in_section(corners, k, plane - probe, centre[:, u], centre[:, v])
            & in_section(corners, k, plane + probe, centre[:, u], centre[:, v]))
    if keep.all():                                      # the whole face: two triangles
        b, h = corner[None, :], g
    else:
        b = base[keep]
    p00, p10, p11, p01 = b, b + h * eu, b + h * (eu + ev), b + h * ev
    # (e_u, e_v, e_k) is right-handed: counter-clockwise in (u, v) faces +e_k
    tri = np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])
    return tri if sign > 0 else tri[:, ::-1].copy()


def in_section(corners: np.ndarray, k: int, plane: float, pu: np.ndarray, pv: np.ndarray) -> np.ndarray:
    """Whether the points (pu, pv) of the plane x_k = ``plane`` lie in the solid's cross-section
    there: the triangles crossing the plane cut it in segments that close into the section's
    outlines (a vertex on the plane counts as above it), and a point is inside where a ray
    along +u crosses them an odd number of times (the crossing rule, half-open in v)."""
    u, v = (k + 1) % 3, (k + 2) % 3
    s = corners[:, :, k] - plane
    above = s >= 0
    cut = above.any(axis=1) & ~above.all(axis=1)
    tri, sd, up = corners[cut], s[cut], above[cut]
    ends = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        cross = up[:, i] != up[:, j]
        t = np.where(cross, sd[:, i] / np.where(cross, sd[:, i] - sd[:, j], 1.0), 0.0)
        ends.append((cross, tri[:, i] + t[:, None] * (tri[:, j] - tri[:, i])))
    # each cut triangle has exactly two crossing edges: its segment's ends
    seg = np.zeros((len(tri), 2, 3))
    filled = np.zeros(len(tri), int)
    for cross, x in ends:
        rows = np.flatnonzero(cross)
        seg[rows, filled[rows]] = x[rows]
        filled[rows] += 1
    au, av, bu, bv = seg[:, 0, u], seg[:, 0, v], seg[:, 1, u], seg[:, 1, v]
    pu, pv = np.asarray(pu, float)[:, None], np.asarray(pv, float)[:, None]
    straddle = (av > pv) != (bv > pv)
    dv = np.where(bv != av, bv - av, 1.0)
    hit = straddle & (pu < au + (pv - av) * (bu - au) / dv)
    return (np.count_nonzero(hit, axis=1) % 2) == 1


def _skin(corners, cells, lo, g, radius, spacing) -> np.ndarray:
    """Contact-sphere centres (n, 3) [m] of the piece: the nodes of the piece's lattice at depth
    r ≤ d < r + a below its surface (dem/mesh_block.py's rule on the piece)."""
    a = lo + g * cells.min(axis=0).astype(float)
    b = lo + g * (cells.max(axis=0) + 1).astype(float)
    axes = lattice_axes(a + radius, b - radius, spacing)
    step = max((ax[1] - ax[0]) if len(ax) > 1 else 0.0 for ax in axes)
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    depth = -piece_distance(nodes, corners, cells, lo, g)
    tol = 1e-9 * g
    return nodes[(depth >= radius - tol) & (depth < radius + max(step, tol))]


def piece_grid(whole: DistanceGrid, piece: GridPiece, lo, g: float, margin: float) -> DistanceGrid:
    """The piece's signed distance max(d_S, d_U) on the nodes of the solid's distance grid
    ``whole`` (d_S there) within its cells' box grown by ``margin`` [m] (file frame)."""
    a = lo + g * piece.cells.min(axis=0).astype(float) - margin
    b = lo + g * (piece.cells.max(axis=0) + 1).astype(float) + margin
    start = whole.centre - whole.half
    step = whole.spacing
    i0 = np.clip(np.floor((a - start) / step + 1e-9).astype(int), 0, whole.dims - 1)
    i1 = np.clip(np.ceil((b - start) / step - 1e-9).astype(int), 0, whole.dims - 1)
    i1 = np.maximum(i1, i0 + 1)
    values = whole.values.reshape(tuple(whole.dims))[i0[0]:i1[0] + 1, i0[1]:i1[1] + 1, i0[2]:i1[2] + 1]
    low, high = start + i0 * step, start + i1 * step
    grid = DistanceGrid(0.5 * (low + high), 0.5 * (high - low), i1 - i0 + 1, np.zeros(0))
    d = np.maximum(values.reshape(-1), union_distance(grid.nodes(), piece.cells, lo, g))
    return DistanceGrid(grid.centre, grid.half, grid.dims, np.ascontiguousarray(d))


# ------------------------------------------------------------------ joining and bonding
def _shared_faces(owner: dict, p: int, q: int):
    """Cell faces between piece p's cells and piece q's: (cell of p, axis k, ±1)."""
    for c, who in owner.items():
        if who != p:
            continue
        for k in range(3):
            for s in (-1, 1):
                nb = list(c)
                nb[k] += s
                if owner.get(tuple(nb)) == q:
                    yield c, k, s


def _largest_neighbour(members: dict, owner: dict, p: int, corners, lo, g) -> int | None:
    """The piece sharing the largest solid face area with piece ``p`` (None: it touches none)."""
    area: dict[int, float] = {}
    for c in members[p]:
        for k in range(3):
            for s in (-1, 1):
                nb = list(c)
                nb[k] += s
                q = owner.get(tuple(nb))
                if q is None or q == p:
                    continue
                pts, w = _face_points(c, k, s, lo, g, 2, corners)
                area[q] = area.get(q, 0.0) + float(w.sum()) + 1e-12 * g * g   # a touching piece wins over none
    return max(area, key=area.get) if area else None


def _face_points(cell, k: int, s: int, lo, g: float, points_per_edge: int, corners):
    """Cohesive points and areas on the face of ``cell`` across axis k towards side s, inside S:
    the Gauss points of the whole face where S covers all those of its 4 × 4 subdivision, else
    the subdivision's, kept where inside."""
    u, v = (k + 1) % 3, (k + 2) % 3
    e = np.eye(3)
    centre = lo + g * (np.asarray(cell, float) + 0.5)
    centre[k] += 0.5 * g * s
    sub = _PARTIAL_SPLIT
    h = g / sub
    ps, ws = [], []
    for i in range(sub):
        for j in range(sub):
            c = centre + (-0.5 * g + (i + 0.5) * h) * e[u] + (-0.5 * g + (j + 0.5) * h) * e[v]
            p_, w_ = face_points(c, e[u], e[v], 0.5 * h, 0.5 * h, points_per_edge)
            ps.append(p_)
            ws.append(w_)
    pts, w = np.concatenate(ps), np.concatenate(ws)
    inside = in_section(corners, k, centre[k], pts[:, u], pts[:, v])
    if inside.all():
        return face_points(centre, e[u], e[v], 0.5 * g, 0.5 * g, points_per_edge)
    return pts[inside], w[inside]


def _bonds(corners, owner: dict, lo, g: float, points_per_edge: int) -> list[GridBond]:
    """One bond per cell face between two pieces, where S covers part of it."""
    bonds = []
    for c, p in sorted(owner.items()):
        for k in range(3):
            nb = list(c)
            nb[k] += 1
            q = owner.get(tuple(nb))
            if q is None or q == p:
                continue
            pts, w = _face_points(c, k, 1, lo, g, points_per_edge, corners)
            if len(w) == 0:
                continue
            a, b, sign = (p, q, 1.0) if p < q else (q, p, -1.0)
            bonds.append(GridBond(a, b, sign * np.eye(3)[k], pts, w))
    return bonds
