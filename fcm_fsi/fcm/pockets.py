"""Fluid pockets that the gap fill seals off, and the vents that reopen them (issue #8).

The gap fill (``levelset._evaluate``) counts fluid gaps narrower than δ ≈ one cell as solid.
Where a block lands on a floor beside a fixed stopper it closes the last gap to the floor
while the corner is still ≈ δ above it, and seals the water between block, stopper and floor
into a pocket of its own. That pocket is incompressible and has no outlet, so the block's
further descent meets an infinitely stiff cushion: in block_overturn (30°, full level) a
784 mm² pocket sealed at ≈ 0.913 s and the next steps gave the 10 N block kicks of ±5 kN
(docs/design-notes.md). In the real gap the water drains until the surfaces touch.

:class:`PocketVents` finds the connected components of the fluid nodes (over the mesh cells,
across MPI ranks) and, while some component other than the largest exists, gives the nodes
of the cells touching it that only the fill made solid their plain level set back — layer by
layer until the pocket reaches the rest of the fluid again — but only fill between owners
that are free to part: one of them a moving block, the other a wall, a static shape, a fixed
block or a block of another bonded cluster. The fill between the blocks of a bonded structure
is its mortar and stays (an enclosed room of a standing building remains a pocket), and so
does the fill between two owners that cannot move (a fixed stopper on the floor).

A pocket no mesh cell lies in entirely (only cut cells, e.g. a sliver of one or two nodes) is
below what the mesh resolves and is left as it is (counted in ``pocket_nodes``, not vented).
Venting such a sliver opened more than it closed: in block_overturn (30°, full level) from
0.751 s a single node, 7 µm inside the fluid at first, in the corner under the tipping block
beside the stopper, counted as a pocket; its vent removed the fill between the block's
lifting underside and the floor, and the sub-cell wedge that opened there pulled the 10 N
block down with up to 12 kN (the first rule, every pocket) or 300–440 N for as long as it was
open (a bound of half a cell's fluid volume, crossed at 0.770 s); left sealed, the same
sliver stays benign (|F_y| < 7 N). The pocket that made the vents (the 784 mm² one at the
landing, 36 nodes) holds whole cells. A bound on depth does not separate the two: the fill's
level is (g − δ)/2 in a gap g, so the landing pocket is only 3.7 mm deep; nor does venting
only closing gaps (the landing pocket, sealed while the block rebounded, kicked the block
with 36 kN at 0.924 s; docs/design-notes.md).

A vent leaves the pocket joined to the rest through a slit narrower than a cell, and the flow
the discrete slit lets through then sets the pocket's pressure: under the 30° block of
block_overturn lying on the stopper and the floor and sliding at 5–10 cm/s, ≈ 2,000 Pa against
≈ 1,300 Pa around it (2.9 N of lift on the 10 N block, docs/coupling.md). With
``coupling.drain_pockets`` :meth:`PocketVents.drainable` names the pockets as the fill seals
them and the main fluid's nodes nearest to each (its rim), and the coupled model holds their
pressure at the rim's, moved hydrostatically — in 3D that water passes the block's sides.
The condition goes on the pocket's inner nodes only (:meth:`PocketVents.inner_nodes`), so the
cut cells keep their continuity equation (pinning every pocket node gave nearly the same loads
in the sliding test: 3.94 against 3.76 N over 0.05–0.1 s).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse.csgraph import connected_components


def fluid_components(cells: np.ndarray, fluid: np.ndarray) -> np.ndarray:
    """Component label (n,) of every node (−1 where not ``fluid``): nodes are joined when a
    cell (rows of node indices) holds both and both are fluid."""
    n = len(fluid)
    ok = fluid[cells]
    rows, cols = [], []
    for a in range(cells.shape[1]):
        for b in range(a + 1, cells.shape[1]):
            both = ok[:, a] & ok[:, b]
            rows.append(cells[both, a])
            cols.append(cells[both, b])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = sp.coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return np.where(fluid, label, -1)


def _one_label(lab: np.ndarray) -> np.ndarray:
    """Per cell (rows of its nodes' labels): all its nodes carry the same label ≥ 0."""
    return np.all(lab == lab[:, :1], axis=1) & (lab[:, 0] >= 0)


def _roots(parent: np.ndarray) -> np.ndarray:
    """Root of every entry of a union-find forest (``parent`` of roots is themselves)."""
    root = parent.copy()
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


class PocketVents:
    """Fluid components across ranks and the vents of :mod:`pockets` (module docstring).

    ``cells`` (nc, nv) local node indices of this rank's cells (owned and ghost), ``global_ids``
    (n,) the global index of every local node, ``owned`` (n,) bool the nodes this rank owns;
    the first ``owned_cells`` of the cells are this rank's own. A pocket is vented when at
    least one cell lies entirely in it.
    """

    def __init__(self, comm: MPI.Comm, cells: np.ndarray, global_ids: np.ndarray, owned: np.ndarray,
                 owned_cells: int | None = None, max_passes: int = 20):
        self.comm, self.cells = comm, np.asarray(cells, np.int64)
        self.global_ids, self.owned = np.asarray(global_ids, np.int64), np.asarray(owned, bool)
        self.max_passes = int(max_passes)
        self.owned_cells = len(self.cells) if owned_cells is None else int(owned_cells)
        self._order = np.argsort(self.global_ids)
        self._sorted_ids = self.global_ids[self._order]
        self.pocket_nodes = 0          # owned fluid nodes outside the largest component (last check; unvented slivers too)
        self.vented_nodes = 0          # owned nodes whose fill was removed (last call)
        self.drained_nodes = 0         # owned nodes of the pockets held at the ambient pressure (last call)

    def components(self, fluid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Global component id (n,) of every fluid node (−1 elsewhere), the same on every rank
        that holds the node, and the owned node count (ncomp,) of each id (collective)."""
        local = fluid_components(self.cells, fluid)
        nloc = int(local.max(initial=-1)) + 1
        offset = self.comm.exscan(nloc) or 0
        total = self.comm.allreduce(nloc)
        gid = np.where(local >= 0, local + offset, -1)
        # join the ids that meet at a node held by several ranks: each ghost's id with its owner's
        shared = fluid & ~self.owned
        pairs = []
        for g_nodes, g_ids in self.comm.allgather((self.global_ids[shared], gid[shared])):
            k = np.minimum(np.searchsorted(self._sorted_ids, g_nodes), len(self._sorted_ids) - 1)
            i = self._order[k]
            mine = (self.global_ids[i] == g_nodes) & self.owned[i] & (gid[i] >= 0)
            pairs.append(np.column_stack([g_ids[mine], gid[i[mine]]]))
        pairs = np.unique(np.concatenate(pairs + [np.zeros((0, 2), np.int64)]), axis=0)
        pairs = np.unique(np.concatenate(self.comm.allgather(pairs)), axis=0)
        parent = np.arange(total)
        for a, b in pairs.tolist():
            ra, rb = _roots(parent)[[a, b]]
            parent[max(ra, rb)] = min(ra, rb)
        root = _roots(parent)
        label = np.where(gid >= 0, root[np.maximum(gid, 0)], -1)
        size = np.bincount(label[self.owned & (label >= 0)], minlength=total)
        return label, self.comm.allreduce(size)

    def vent(self, level: np.ndarray, plain_level, ventable: np.ndarray, combine) -> np.ndarray:
        """Remove the fill where it seals fluid pockets: ``level`` (n,) the level set with the fill
        (changed in place), ``plain_level()`` the level set without it (called only if some fill
        next to a pocket may go), ``ventable`` (n,) bool where the fill may go (between owners
        free to part). Only nodes that the fill made solid (level ≤ 0 < plain) and that share a cell with the pocket
        go back to the plain level set, so the fill is opened no wider than needed; pockets that no
        cell lies in entirely are not vented;
        ``combine(flags)`` makes per-node flags agree across ranks (logical or over the ranks
        holding a node). Returns the nodes reverted to the plain level set (collective)."""
        reverted = np.zeros(len(level), bool)
        self.pocket_nodes = 0
        for _ in range(self.max_passes):
            label, size = self.components(level > 0)
            if np.count_nonzero(size) <= 1:
                break
            if not self.pocket_nodes:
                self.pocket_nodes = int(size.sum() - size.max())
            big = int(np.argmax(size))
            fluid = label >= 0
            resolved = self.whole_cells(label, len(size)) > 0
            resolved[big] = False
            pocket = fluid & resolved[np.maximum(label, 0)]
            if not self.comm.allreduce(bool(pocket.any()), op=MPI.LOR):
                break
            candidate = self._cell_neighbours(pocket) & ventable & (level <= 0)
            if not self.comm.allreduce(bool(candidate.any()), op=MPI.LOR):
                break
            plain = plain_level()
            revert = combine(candidate & (plain > 0))
            if not self.comm.allreduce(bool(revert.any()), op=MPI.LOR):
                break
            level[revert] = plain[revert]
            reverted |= revert
        self.vented_nodes = self.comm.allreduce(int(np.count_nonzero(reverted & self.owned)))
        return reverted

    def drainable(self, level: np.ndarray, ventable: np.ndarray, combine,
                  max_layers: int = 4) -> tuple[np.ndarray, np.ndarray]:
        """The pockets that ``coupling.drain_pockets`` holds at the ambient pressure, and where
        that pressure is read: ``level`` (n,) the level set with the fill (unchanged),
        ``ventable`` and ``combine`` as in :meth:`vent`. A pocket qualifies as for a vent: it
        holds a whole cell and touches fill between owners free to part. Returns ``pocket``
        (n,) int, the index k = 0, 1, … of the drained pocket each node is in (−1 elsewhere,
        the same on every rank), and ``rim`` (n,) int, k on the nodes of the main fluid (the
        largest component) that the first of up to ``max_layers`` cell layers grown from
        pocket k reaches (−1 elsewhere). Collective."""
        n = len(level)
        pocket, rim = np.full(n, -1, np.int64), np.full(n, -1, np.int64)
        label, size = self.components(level > 0)
        self.pocket_nodes = int(size.sum() - size.max()) if np.count_nonzero(size) > 1 else 0
        self.drained_nodes = 0
        if np.count_nonzero(size) <= 1:
            return pocket, rim
        big = int(np.argmax(size))
        resolved = self.whole_cells(label, len(size)) > 0
        resolved[big] = False
        k = 0
        for c in np.flatnonzero(resolved):
            inside = label == c
            near = self._cell_neighbours(inside)
            if not self.comm.allreduce(bool((near & ventable & (level <= 0)).any()), op=MPI.LOR):
                continue               # sealed by mortar or by owners that cannot part
            pocket[inside] = k
            grown = inside
            for _ in range(max_layers):
                grown = combine(self._cell_neighbours(grown))
                ring = grown & (label == big)
                if self.comm.allreduce(bool(ring.any()), op=MPI.LOR):
                    rim[ring & (rim < 0)] = k
                    break
            k += 1
        self.drained_nodes = self.comm.allreduce(int(np.count_nonzero((pocket >= 0) & self.owned)))
        return pocket, rim

    def inner_nodes(self, pocket: np.ndarray, combine) -> np.ndarray:
        """Nodes (n,) bool of the drained pockets whose every cell lies in the same pocket (no
        cut cell touches them), from ``pocket`` of :meth:`drainable`. Collective."""
        whole = _one_label(pocket[self.cells])
        touched = np.zeros(len(pocket), bool)
        touched[self.cells[~whole].ravel()] = True
        return (pocket >= 0) & ~combine(touched)

    def _cell_neighbours(self, flags: np.ndarray) -> np.ndarray:
        """``flags`` and the nodes that share a cell with a flagged node (this rank's cells)."""
        out = flags.copy()
        out[self.cells[flags[self.cells].any(axis=1)].ravel()] = True
        return out

    def whole_cells(self, label: np.ndarray, ncomp: int) -> np.ndarray:
        """Number (ncomp,) of the cells whose nodes all belong to each component, summed over the
        ranks' own cells (collective)."""
        lab = label[self.cells[: self.owned_cells]]
        whole = _one_label(lab)
        count = np.bincount(lab[whole, 0], minlength=ncomp).astype(np.int64)
        self.comm.Allreduce(MPI.IN_PLACE, count, op=MPI.SUM)
        return count
