"""The peer benchmark's own pieces, without OpenFOAM: the case it writes for interFoam matches
ours (tank, cell count), its front is read and scored as ours, and the impact mesh's cell size."""
from __future__ import annotations

import re

import numpy as np
import pytest

from fcm_fsi.bench import _openfoam, peer
from fcm_fsi.verify.cases.two_phase import DAM_HEIGHT, DAM_LENGTH, MM_A, best_time_shift, front_deviation


def test_interfoam_dam_break_mesh_is_our_tank_and_cell_count(tmp_path):
    _openfoam.dam_break_block_mesh(tmp_path, 120, 50, 6 * MM_A / 120)
    text = (tmp_path / "system" / "blockMeshDict").read_text()
    assert "(120 50 1)" in text
    vertices = text.split("vertices")[1].split(";")[0]
    xyz = np.array([float(w) for w in re.findall(r"[-+]?\d*\.?\d+(?:[eE][-+]?\d+)?", vertices)]).reshape(-1, 3)
    assert xyz[:, 0].max() == pytest.approx(DAM_LENGTH) and xyz[:, 1].max() == pytest.approx(DAM_HEIGHT)
    assert xyz.min() == 0.0


def test_interfoam_front_is_scored_as_ours(tmp_path):
    """An interFoam-style series (t, wetted length) that is Martin & Moyce's front delayed by 0.2 in
    T gives the delay back and a small deviation after it."""
    from fcm_fsi.verify.cases.two_phase import MM_FRONT
    T = np.linspace(0.0, 3.5, 200)
    Z = np.interp(T + 0.2, MM_FRONT[:, 0], MM_FRONT[:, 1], left=1.0)
    shift, dev = best_time_shift(T, Z)
    assert shift == pytest.approx(0.2, abs=0.01) and dev < 0.02
    assert front_deviation(T, Z) > 0.1


def test_impact_hex_size_fills_the_tank_with_the_given_cells():
    size = peer.hex_size(114_124)
    assert (12 * 4 * 6 - 1 * 1.6 * 2) / size ** 3 == pytest.approx(114_124)
    assert peer.ratio_row(2, {"process": 4.0, "solver": 3.0, "steps": 10}, {"process": 2.0, "solver": 1.0, "steps": 5}) \
        .split() == ["ratio", "2.00", "3.00", "2.00"]


def test_repeated_runs_report_the_median_times():
    runs = [{"process": p, "solver": s, "steps": 76, "dev": 0.3} for p, s in ((9.0, 7.0), (12.0, 9.0), (10.0, 8.5))]
    m = peer.median_run(runs)
    assert (m["process"], m["solver"], m["steps"], m["repeats"]) == (10.0, 8.5, 76, 3)


def test_load_error_is_the_relative_l1_distance_of_the_histories():
    t = np.linspace(0.0, 1.0, 201)
    ref = {"t": t, "fx": np.full_like(t, 100.0)}
    assert peer.load_error({"t": t[::2], "fx": np.full(101, 110.0)}, ref) == pytest.approx(0.1)
    assert peer.load_error(ref, ref) == 0.0
