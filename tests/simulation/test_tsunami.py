"""The tsunami building case (issue #9) as shipped: its first fluid steps on 2 ranks.

The verification's quick level (1.5 s, ≈ 10 min on 2 ranks) and full level (10 s) are run by
``python -m fcm_fsi verify tsunami_building``; this is the CI slice of the same case file: the
`coarse` mesh, the founded 208-block building and the case's coupling settings, 0.06 s —
before the water arrives, so the building must stand still on its foundation.
"""
from __future__ import annotations

import numpy as np

from tests.conftest import ROOT, run_cli
from tests.simulation.test_coupled import read


def test_tsunami_case_starts_with_the_building_at_rest_on_two_ranks(tmp_path):
    out = tmp_path / "tsunami"
    run = run_cli([str(ROOT / "cases" / "tsunami_building.yaml"), "--output", str(out),
                   "--set", "run.t_end=0.06", "--set", "output.xdmf=false"], np_=2, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    series = read(out / "series.csv")
    assert series["t"][-1] == np.float64(0.06)
    assert np.abs(series["liquid_volume_error"]).max() < 5e-3          # the verification's bound
    assert series["exchange_error"].max() < 1e-10
    assert series["broken_bonds"][-1] == 0
    # the case iterates the coupling (up to 6 passes) but the intact building and its foundation
    # are one fixed cluster, so one pass converges: no extra cost before the first break
    assert np.all(series["coupling_iterations"] == 1)
    bodies = read(out / "bodies.csv")
    nb = int(bodies["block"].max()) + 1
    assert nb == 209                                                    # 208 blocks + the foundation
    z = bodies["z"].reshape(-1, nb)
    sink = np.abs(z - z[0]).max()
    # a building that started above the ground (origin z 0.1 m) falls at g t:
    # 17.7 mm by 0.06 s; standing on its foundation it only settles into its contacts and bonds
    # (1.2 mm measured; they ring at up to 0.1 m/s over a period 2π√(m/k) ≈ 40 ms)
    assert sink < 5e-3
    # member_loads.csv: each member's largest traction / σ_c so far, one row per step, the same
    # as the final checkpoint's λ_max gives; an envelope, so it never falls
    from fcm_fsi.config import load_case
    from fcm_fsi.dem.bond_report import bonded_structure_of, member_peak_tractions, read_bond_state
    from fcm_fsi.dem.failure_sequence import block_members
    loads = read(out / "member_loads.csv")
    case = load_case(ROOT / "cases" / "tsunami_building.yaml")
    members = block_members(case)
    _, bonds = bonded_structure_of(case, with_ledger=False)
    final = member_peak_tractions(bonds, *read_bond_state(out / "checkpoint.h5"), members)
    assert set(loads) == {"t"} | {m.replace(" ", "_") for m in final}
    np.testing.assert_array_equal(loads["t"], series["t"][1:])
    for m, v in final.items():
        col = loads[m.replace(" ", "_")]
        assert np.all(np.diff(col) >= 0) and col[-1] == v
        assert 0.0 <= v < 1.0                      # the ringing loads the bonds, breaks none
    assert final["foundation"] > 0.0
    # a restart continues the file: the earlier rows stay, the new ones follow
    more = run_cli([str(ROOT / "cases" / "tsunami_building.yaml"), "--output", str(out), "--restart",
                    str(out / "checkpoint.h5"), "--set", "run.t_end=0.08", "--set", "output.xdmf=false"],
                   np_=2, timeout=900)
    assert more.returncode == 0, more.stderr[-3000:]
    again = read(out / "member_loads.csv")
    np.testing.assert_array_equal(again["t"], read(out / "series.csv")["t"][1:])
    assert again["t"][-1] == np.float64(0.08)
    np.testing.assert_array_equal(again["wall_xmin_s0"][: len(loads["t"])], loads["wall_xmin_s0"])
