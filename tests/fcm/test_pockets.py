"""Fluid pockets sealed by the gap fill, and their vents (fcm/pockets.py)."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from mpi4py import MPI

from fcm_fsi.fcm.pockets import PocketVents, fluid_components
from tests.conftest import ROOT, mpi_env


def grid(n):
    """Nodes (n+1)² of the unit square and its right triangles (two per square)."""
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    cells = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return np.column_stack([x.ravel(), y.ravel()]), cells


C = (0.5013, 0.4987)


def ring_with_slot(p):
    """Level sets (> 0 fluid) of an annulus 0.2 < r < 0.3 about c = (0.5013, 0.4987): ``plain``
    with a slot 0.1 wide in it (the fluid inside connects to the outside), ``filled`` without
    (the gap fill closing the slot seals the inside off). c is off the grid's lines so that no
    node lies on a surface (where rounding would decide which side it is on)."""
    r = np.hypot(p[:, 0] - C[0], p[:, 1] - C[1])
    filled = np.abs(r - 0.25) - 0.05
    slot = np.abs(p[:, 1] - C[1]) - 0.05
    plain = np.where((p[:, 0] > C[0]) & (slot < 0), np.maximum(filled, -slot), filled)
    return plain, filled


def test_components_of_a_sealed_ring_and_its_slot():
    p, cells = grid(40)
    plain, filled = ring_with_slot(p)
    inside = np.hypot(p[:, 0] - C[0], p[:, 1] - C[1]) < 0.2
    lab = fluid_components(cells, filled > 0)
    assert np.all(lab[filled <= 0] == -1)
    assert len(np.unique(lab[lab >= 0])) == 2 and len(np.unique(lab[inside])) == 1
    assert lab[inside][0] != lab[0]
    assert len(np.unique(fluid_components(cells, plain > 0)[plain > 0])) == 1


def _vents(cells, n):
    return PocketVents(MPI.COMM_SELF, cells, np.arange(n), np.ones(n, bool))


def test_vent_removes_the_fill_that_seals_a_pocket_and_only_there():
    p, cells = grid(40)
    plain, filled = ring_with_slot(p)
    level = filled.copy()
    vents = _vents(cells, len(p))
    reverted = vents.vent(level, lambda: plain, np.ones(len(p), bool), lambda f: f)
    inside = np.hypot(p[:, 0] - C[0], p[:, 1] - C[1]) < 0.2
    assert vents.pocket_nodes == np.count_nonzero(filled[inside] > 0) > 100
    assert len(np.unique(fluid_components(cells, level > 0)[level > 0])) == 1      # reopened
    assert 0 < reverted.sum() == vents.vented_nodes and np.all(plain[reverted] != filled[reverted])
    slot = (p[:, 0] > C[0]) & (np.abs(p[:, 1] - C[1]) < 0.05)
    assert np.all(slot[reverted])                           # the fill goes only in the slot
    assert np.all(level[~reverted] == filled[~reverted])


def test_bonded_fill_stays_and_a_pocket_without_fill_stays():
    p, cells = grid(40)
    plain, filled = ring_with_slot(p)
    vents = _vents(cells, len(p))
    level = filled.copy()
    assert not vents.vent(level, lambda: plain, np.zeros(len(p), bool), lambda f: f).any()   # mortar
    assert np.array_equal(level, filled) and vents.pocket_nodes > 100
    level = filled.copy()        # a room enclosed by the structure itself: nothing to vent
    assert not vents.vent(level, lambda: filled, np.ones(len(p), bool), lambda f: f).any()
    level = plain.copy()         # no pocket: the plain level set is never asked for
    assert not vents.vent(level, lambda: pytest.fail("plain level set evaluated"), np.ones(len(p), bool),
                          lambda f: f).any() and vents.pocket_nodes == 0


def test_a_sliver_pocket_without_a_whole_cell_stays():
    """A pocket of one fluid node (every cell touching it cut) is below what the mesh resolves:
    counted, not vented; the ring's pocket holds whole cells and is vented (the other tests)."""
    p, cells = grid(40)
    plain, filled = ring_with_slot(p)
    r = np.hypot(p[:, 0] - C[0], p[:, 1] - C[1])
    level = np.where((filled > 0) & (r >= 0.2), 1.0, -1e-3)     # the ring and its inside solid ...
    i = int(np.argmin(r))
    level[i] = 1e-6                                              # ... but for one node at the centre
    before = level.copy()
    vents = _vents(cells, len(p))
    assert not vents.vent(level, lambda: plain, np.ones(len(p), bool), lambda f: f).any()
    assert np.array_equal(level, before) and vents.pocket_nodes == 1 and vents.vented_nodes == 0
    label, size = vents.components(level > 0)
    counts = vents.whole_cells(label, len(size))
    assert counts[label[i]] == 0 and counts[int(np.argmax(size))] > 1000


def test_drainable_pocket_its_rim_and_inner_nodes():
    """coupling.drain_pockets: the sealed inside of the ring is pocket 0, its rim is main fluid
    just outside the ring (reached through the ring's solid), and its inner nodes are the
    pocket nodes no cut cell touches; mortar (not ventable) seals a pocket that is not drained."""
    p, cells = grid(40)
    _, filled = ring_with_slot(p)
    r = np.hypot(p[:, 0] - C[0], p[:, 1] - C[1])
    vents = _vents(cells, len(p))
    pocket, rim = vents.drainable(filled, np.ones(len(p), bool), lambda f: f, max_layers=8)
    assert np.array_equal(pocket >= 0, (filled > 0) & (r < 0.2)) and set(np.unique(pocket)) == {-1, 0}
    assert vents.drained_nodes == vents.pocket_nodes == np.count_nonzero(pocket == 0)
    assert rim.max() == 0 and np.all(r[rim == 0] > 0.3) and np.all(filled[rim == 0] > 0)
    assert np.all(r[rim == 0] < 0.3 + 6 / 40)                    # the first layers beyond the ring
    inner = vents.inner_nodes(pocket, lambda f: f)
    for i in range(len(p)):                                      # brute force: every cell of i in the pocket
        mine = np.any(cells == i, axis=1)
        assert inner[i] == bool(pocket[i] == 0 and np.all(pocket[cells[mine]] == 0))
    assert 0 < inner.sum() < (pocket == 0).sum()
    pocket, rim = vents.drainable(filled, np.zeros(len(p), bool), lambda f: f, max_layers=8)
    assert np.all(pocket < 0) and np.all(rim < 0) and vents.pocket_nodes > 100 and vents.drained_nodes == 0


MPI_SCRIPT = r"""
import json, numpy as np
from mpi4py import MPI
from dolfinx import fem, la, mesh
from fcm_fsi.fcm.pockets import PocketVents
comm = MPI.COMM_WORLD
m = mesh.create_unit_square(comm, 40, 40, ghost_mode=mesh.GhostMode.shared_facet)
S = fem.FunctionSpace(m, ("Lagrange", 1))
imap = S.dofmap.index_map
n = imap.size_local + imap.num_ghosts
cells = S.dofmap.list.array.reshape(-1, 3)
p = S.tabulate_dof_coordinates()[:n]
from tests.fcm.test_pockets import ring_with_slot
plain, filled = ring_with_slot(p)
owned = np.arange(n) < imap.size_local
vents = PocketVents(comm, cells, imap.local_to_global(np.arange(n, dtype=np.int32)), owned,
                    m.topology.index_map(2).size_local)
f = fem.Function(S)
def any_rank(flags):
    f.x.array[:] = 0.0
    f.x.array[:n] = flags
    f.x.scatter_reverse(la.ScatterMode.add)
    f.x.scatter_forward()
    return f.x.array[:n] > 0
label, size = vents.components(filled > 0)
level = filled.copy()
reverted = vents.vent(level, lambda: plain, np.ones(n, bool), any_rank)
after, size_after = vents.components(level > 0)
pk, rm = vents.drainable(filled, np.ones(n, bool), any_rank, max_layers=8)
inner = vents.inner_nodes(pk, any_rank)
drain = [comm.allreduce(int(np.count_nonzero(a & owned))) for a in (pk >= 0, rm >= 0, inner)]
g = imap.local_to_global(np.arange(n, dtype=np.int32))
rows = comm.gather(np.column_stack([g, label, after, reverted, pk, rm, inner]), root=0)
if comm.rank == 0:
    allrows = np.concatenate(rows)
    consistent = all(len(np.unique(allrows[allrows[:, 0] == k][:, 1:], axis=0)) == 1
                     for k in np.unique(allrows[:, 0]))
    print("RESULT" + json.dumps({"components": int(np.count_nonzero(size)), "after": int(np.count_nonzero(size_after)),
                                 "pocket": vents.pocket_nodes, "vented": vents.vented_nodes,
                                 "consistent": bool(consistent), "ranks": comm.size, "drain": drain}))
"""


@pytest.mark.mpi
def test_components_and_vents_agree_on_1_and_2_ranks():
    """The same pocket, the same vent (and the same drained pocket, rim and inner nodes) on 1
    and 2 ranks, and every rank that holds a node gives it the same component and the same
    decisions."""
    res = []
    for ranks in (1, 2):
        cmd = [shutil.which("mpirun"), "-n", str(ranks), sys.executable, "-c", MPI_SCRIPT]
        out = subprocess.run(cmd, cwd=ROOT, env=mpi_env(), stdin=subprocess.DEVNULL, capture_output=True,
                             text=True, timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]
        res.append(json.loads([ln for ln in out.stdout.splitlines() if ln.startswith("RESULT")][0][6:]))
    for r in res:
        assert r["components"] == 2 and r["after"] == 1 and r["consistent"] and r["pocket"] > 100
    assert res[0]["pocket"] == res[1]["pocket"] and res[0]["vented"] == res[1]["vented"] > 0
    assert res[0]["drain"] == res[1]["drain"] and min(res[0]["drain"]) > 0     # drained, rim, inner nodes
