"""O(N) neighbour search: a Numba cell list that builds a Verlet pair list with a skin.

Pairs (i < j) of spheres on *different* blocks whose gap is below ``skin`` at build time
are listed: |x_i − x_j| < r_i + r_j + skin. Rebuild criterion: the list is rebuilt when
any sphere has moved more than skin/2 since the last build (translation and rotation
of its block both count, because the sphere's world centre is compared). Two spheres
then cannot have closed a gap larger than the skin, so no contact is ever missed.

Cells are cubes of edge ≥ 2 r_max + skin over the bounding box of the spheres at build
time, sorted by a counting sort; each sphere scans its own and the 26 neighbouring cells.
Cost O(N) per build; the grid edge is enlarged if the box would need more than 4 N cells
(scattered spheres), which keeps memory O(N).

Also built: a CSR "sphere → pairs" map (``sp_start``, ``sp_pair``, ``sp_sign``) so that
pair forces can be gathered per sphere in parallel without write races.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from ..geometry import sort_by_cell


@nb.njit(cache=True)
def _grid(sph_pos, cell):
    ns = sph_pos.shape[0]
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = sph_pos[:, d].min()
        hi[d] = sph_pos[:, d].max()
    while True:
        dims = np.empty(3, np.int64)
        for d in range(3):
            dims[d] = int((hi[d] - lo[d]) / cell) + 1
        if dims[0] * dims[1] * dims[2] <= 4 * ns + 64:
            break
        cell *= 1.26
    return lo, dims, cell


@nb.njit(cache=True)
def _cell_sort(sph_pos, lo, dims, cell):
    ns = sph_pos.shape[0]
    cid = np.empty(ns, np.int64)
    for s in range(ns):
        cx = min(int((sph_pos[s, 0] - lo[0]) / cell), dims[0] - 1)
        cy = min(int((sph_pos[s, 1] - lo[1]) / cell), dims[1] - 1)
        cz = min(int((sph_pos[s, 2] - lo[2]) / cell), dims[2] - 1)
        cid[s] = (cx * dims[1] + cy) * dims[2] + cz
    start, order = sort_by_cell(cid, dims[0] * dims[1] * dims[2])
    return cid, start, order


@nb.njit(cache=True)
def _scan(i, sph_pos, sph_radius, sph_block, skin, cid, start, order, dims, out_j, write):
    """Partners j > i of sphere i within the skin; returns their count (writes if write)."""
    c = cid[i]
    cz = c % dims[2]
    cy = (c // dims[2]) % dims[1]
    cx = c // (dims[1] * dims[2])
    n = 0
    for ax in range(max(cx - 1, 0), min(cx + 2, dims[0])):
        for ay in range(max(cy - 1, 0), min(cy + 2, dims[1])):
            for az in range(max(cz - 1, 0), min(cz + 2, dims[2])):
                cc = (ax * dims[1] + ay) * dims[2] + az
                for k in range(start[cc], start[cc + 1]):
                    j = order[k]
                    if j <= i or sph_block[j] == sph_block[i]:
                        continue
                    dx = sph_pos[j, 0] - sph_pos[i, 0]
                    dy = sph_pos[j, 1] - sph_pos[i, 1]
                    dz = sph_pos[j, 2] - sph_pos[i, 2]
                    reach = sph_radius[i] + sph_radius[j] + skin
                    if dx * dx + dy * dy + dz * dz < reach * reach:
                        if write:
                            out_j[n] = j
                        n += 1
    return n


@nb.njit(cache=True, parallel=True)
def build_pairs(sph_pos, sph_radius, sph_block, skin):
    """Pair list (npair, 2) int64, i < j, rows sorted by (i, j)."""
    ns = sph_pos.shape[0]
    rmax = sph_radius.max()
    lo, dims, cell = _grid(sph_pos, 2.0 * rmax + skin)
    cid, start, order = _cell_sort(sph_pos, lo, dims, cell)
    count = np.zeros(ns + 1, np.int64)
    dummy = np.empty(0, np.int64)
    for i in nb.prange(ns):
        count[i + 1] = _scan(i, sph_pos, sph_radius, sph_block, skin, cid, start, order, dims, dummy, False)
    for i in range(ns):
        count[i + 1] += count[i]
    pairs = np.empty((count[ns], 2), np.int64)
    for i in nb.prange(ns):
        m = count[i + 1] - count[i]
        if m == 0:
            continue
        buf = np.empty(m, np.int64)
        _scan(i, sph_pos, sph_radius, sph_block, skin, cid, start, order, dims, buf, True)
        buf.sort()
        for k in range(m):
            pairs[count[i] + k, 0] = i
            pairs[count[i] + k, 1] = buf[k]
    return pairs


@nb.njit(cache=True)
def sphere_pair_map(pairs, ns):
    """CSR map sphere → (pair index, sign): +1 when the sphere is pairs[p,0], −1 for pairs[p,1]."""
    npair = pairs.shape[0]
    start = np.zeros(ns + 1, np.int64)
    for p in range(npair):
        start[pairs[p, 0] + 1] += 1
        start[pairs[p, 1] + 1] += 1
    for s in range(ns):
        start[s + 1] += start[s]
    fill = start[:-1].copy()
    idx = np.empty(2 * npair, np.int64)
    sign = np.empty(2 * npair, np.float64)
    for p in range(npair):
        i = pairs[p, 0]
        j = pairs[p, 1]
        idx[fill[i]] = p
        sign[fill[i]] = 1.0
        fill[i] += 1
        idx[fill[j]] = p
        sign[fill[j]] = -1.0
        fill[j] += 1
    return start, idx, sign


@nb.njit(cache=True)
def carry_history(old_pairs, old_hist, new_pairs, ns):
    """Contact history of pairs present in both lists is copied, new pairs start at 0.
    Both lists have rows sorted by (i, j): one merge pass, O(old + new); only non-zero old
    rows are copied."""
    new_hist = np.zeros((new_pairs.shape[0], old_hist.shape[1]))
    m = old_hist.shape[1]
    p = 0
    npn = new_pairs.shape[0]
    for k in range(old_pairs.shape[0]):
        nz = False
        for d in range(m):
            if old_hist[k, d] != 0.0:
                nz = True
                break
        if not nz:
            continue
        key = old_pairs[k, 0] * ns + old_pairs[k, 1]
        while p < npn and new_pairs[p, 0] * ns + new_pairs[p, 1] < key:
            p += 1
        if p < npn and new_pairs[p, 0] * ns + new_pairs[p, 1] == key:
            for d in range(m):
                new_hist[p, d] = old_hist[k, d]
    return new_hist


@nb.njit(cache=True, parallel=True)
def max_displacement(sph_pos, ref_pos):
    """Largest |x_s − x_s,ref| over all spheres."""
    ns = sph_pos.shape[0]
    d2 = np.zeros(ns)
    for s in nb.prange(ns):
        dx = sph_pos[s, 0] - ref_pos[s, 0]
        dy = sph_pos[s, 1] - ref_pos[s, 1]
        dz = sph_pos[s, 2] - ref_pos[s, 2]
        d2[s] = dx * dx + dy * dy + dz * dz
    return np.sqrt(d2.max()) if ns > 0 else 0.0


def build_pairs_ref(sph_pos, sph_radius, sph_block, skin):
    """NumPy/SciPy reference of :func:`build_pairs` (k-d tree), same ordering."""
    from scipy.spatial import cKDTree
    if len(sph_pos) < 2:
        return np.zeros((0, 2), np.int64)
    tree = cKDTree(sph_pos)
    cand = tree.query_pairs(2 * sph_radius.max() + skin, output_type="ndarray")
    if len(cand) == 0:
        return np.zeros((0, 2), np.int64)
    i, j = cand.min(1), cand.max(1)
    d = np.linalg.norm(sph_pos[j] - sph_pos[i], axis=1)
    keep = (d < sph_radius[i] + sph_radius[j] + skin) & (sph_block[i] != sph_block[j])
    p = np.stack([i[keep], j[keep]], axis=1).astype(np.int64)
    return p[np.lexsort((p[:, 1], p[:, 0]))]


class NeighbourList:
    """Verlet list with skin over the spheres of a state (rebuilt on demand)."""

    def __init__(self, skin: float):
        self.skin = float(skin)
        self.pairs = np.zeros((0, 2), np.int64)
        self.ref_pos = None
        self.builds = 0
        self.sp_start = self.sp_pair = self.sp_sign = None

    def needs_rebuild(self, sph_pos: np.ndarray) -> bool:
        if self.ref_pos is None or self.ref_pos.shape != sph_pos.shape:
            return True
        return max_displacement(sph_pos, self.ref_pos) > 0.5 * self.skin

    def rebuild(self, sph_pos, sph_radius, sph_block) -> np.ndarray:
        """Build the new pair list; returns the old one (for history carry-over)."""
        old = self.pairs
        self.pairs = build_pairs(sph_pos, sph_radius, sph_block, self.skin)
        self.sp_start, self.sp_pair, self.sp_sign = sphere_pair_map(self.pairs, sph_pos.shape[0])
        self.ref_pos = sph_pos.copy()
        self.builds += 1
        return old
