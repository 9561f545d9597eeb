"""fcm_fsi/geometry.py: the counting sort of points by cell against its NumPy twin."""
from __future__ import annotations

import numpy as np

from fcm_fsi.geometry import sort_by_cell, sort_by_cell_np


def test_sort_by_cell_equals_its_numpy_twin_and_groups_every_point_once():
    rng = np.random.default_rng(3)
    ncell = 37
    cell = rng.integers(0, ncell, 1000).astype(np.int64)
    start, order = sort_by_cell(cell, ncell)
    start_np, order_np = sort_by_cell_np(cell, ncell)
    assert np.array_equal(start, start_np) and np.array_equal(order, order_np)
    assert np.array_equal(np.sort(order), np.arange(cell.size))
    for c in range(ncell):
        members = order[start[c]:start[c + 1]]
        assert np.all(cell[members] == c) and np.all(np.diff(members) > 0)
