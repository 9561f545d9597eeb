"""Structure builder: the paper building, surface spheres, mass, bonds on touching faces, errors."""
from pathlib import Path

import numpy as np
import pytest

from fcm_fsi.config.loader import ConfigError, build
from fcm_fsi.config.structure import CohesiveConfig, StructureConfig
from fcm_fsi.dem.builder import KINDS, PAPER_BUILDING, assemble, build_building, load_structure, paper_building
from fcm_fsi.dem.cohesive import CohesiveLaw

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def paper():
    cfg, coh = paper_building()
    return cfg, coh, build_building(cfg)


def test_structure_and_cohesive_sections_read_from_a_case_file(tmp_path):
    import yaml
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump({"name": "b", "dem": dict(PAPER_BUILDING)}))
    assert load_structure(path) == paper_building()
    bad = {"name": "b", "dem": {"structure": {**PAPER_BUILDING["structure"], "storys": 2}}}
    path.write_text(yaml.safe_dump(bad))
    with pytest.raises(ConfigError, match="dem.structure.storys.*did you mean"):
        load_structure(path)


def brute_force_touching(lo, hi, tol=1e-9):
    pairs = set()
    n = len(lo)
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            for k in range(3):
                o = [a for a in range(3) if a != k]
                if abs(hi[i, k] - lo[j, k]) < tol and np.all(
                        np.minimum(hi[i, o], hi[j, o]) - np.maximum(lo[i, o], lo[j, o]) > tol):
                    pairs.add((i, j))
    return pairs


def test_paper_building_has_208_blocks(paper):
    cfg, coh, s = paper
    assert s.nb == 208
    assert coh.sigma_c == 1.0e7 and coh.delta_f == 0.02 and cfg.sphere_radius == 0.1
    counts = dict(zip(KINDS, np.bincount(s.kind, minlength=len(KINDS))))
    assert counts["column"] == 2 * 4 * 4  # 4 columns × 4 lifts × 2 storeys


def test_blocks_do_not_overlap_and_bonds_are_exactly_the_touching_faces(paper):
    _, _, s = paper
    lo, hi = s.lo, s.hi
    inter = np.minimum(hi[:, None], hi[None]) - np.maximum(lo[:, None], lo[None])
    overlap = np.all(inter > 1e-9, axis=2)
    np.fill_diagonal(overlap, False)
    assert not overlap.any()
    got = {(f.a, f.b) for f in s.faces}
    assert len(got) == len(s.faces)
    assert got == brute_force_touching(lo, hi)
    for f in s.faces:  # shared rectangle lies on both boxes' faces
        c = np.array(f.centre)
        assert np.all(c >= lo[f.a] - 1e-9) and np.all(c <= hi[f.a] + 1e-9)
        assert np.all(c >= lo[f.b] - 1e-9) and np.all(c <= hi[f.b] + 1e-9)


def test_door_is_open(paper):
    cfg, _, s = paper
    op = cfg.openings[0]
    c = s.pos
    y0 = cfg.origin[1] + cfg.column[1] / 2 + op.offset
    inside = ((np.abs(c[:, 0] - cfg.origin[0]) < cfg.wall_thickness)
              & (c[:, 1] > y0) & (c[:, 1] < y0 + op.width) & (c[:, 2] < op.height))
    assert not inside.any()


def test_spheres_sit_on_the_surface_and_mass_from_the_solid_box(paper):
    cfg, _, s = paper
    r = cfg.sphere_radius
    half = 0.5 * (s.hi - s.lo)[s.sph_block]
    gap = half - (np.abs(s.sph_local) + r)  # ≥ 0 inside; 0 on the face it touches
    assert gap.min() > -1e-12
    assert np.all(gap.min(axis=1) < 1e-12)
    vol = np.prod(s.hi - s.lo, axis=1)
    np.testing.assert_allclose(s.mass, cfg.density * vol, rtol=1e-14)
    # a 1 × 0.4 × 0.4 column block: I_x = m(0.4² + 0.4²)/12
    col = np.flatnonzero(s.kind == KINDS.index("column"))[0]
    e = s.hi[col] - s.lo[col]
    assert s.inertia[col, 0] == pytest.approx(s.mass[col] * (e[1] ** 2 + e[2] ** 2) / 12)


def test_built_structure_is_stress_free(paper):
    cfg, coh, s = paper
    bonds = s.bonds(CohesiveLaw.from_config(coh), coh.points_per_edge)
    f = np.zeros((s.nb, 3))
    t = np.zeros((s.nb, 3))
    bonds.compute(s.pos, s.quat, f, t)
    assert np.abs(f).max() < 1e-6 and np.abs(t).max() < 1e-6
    assert bonds.n_bonds == len(s.faces) and bonds.n_points == 4 * len(s.faces)
    np.testing.assert_allclose(np.bincount(bonds.pt_bond, bonds.pt_area), bonds.bond_area)


def cfg_dict(**changes):
    d = dict(storeys=1, storey_height=3.0, bays_x=[4.0], bays_y=[4.0], column=[0.4, 0.4],
             wall_thickness=0.2, slab_thickness=0.2, block_size=1.0, sphere_radius=0.1,
             material="concrete", density=2400.0)
    d.update(changes)
    return d


@pytest.mark.parametrize("changes, words", [
    (dict(wall_thickness=0.6), "wall_thickness"),
    (dict(density=-1.0), "density"),
    (dict(walls=["xmin", "front"]), "walls"),
    (dict(colum=[0.4, 0.4]), "did you mean"),
    (dict(openings=[dict(storey=0, side="xmin", bay=0, offset=3.0, width=1.0, height=2.0)]), "panel length"),
    (dict(openings=[dict(storey=2, side="xmin", bay=0, offset=0.0, width=1.0, height=2.0)]), "storeys"),
    (dict(walls=["xmin"], openings=[dict(storey=0, side="ymin", bay=0, offset=0.0, width=1.0, height=2.0)]), "no wall"),
])
def test_structure_config_errors(changes, words):
    with pytest.raises(ConfigError, match=words):
        build(StructureConfig, cfg_dict(**changes), "case.yaml", prefix="dem.structure")


def test_density_comes_from_the_material_when_not_given():
    cfg = build(StructureConfig, cfg_dict(density=None))
    s = build_building(cfg, material_index=2, material_density=2000.0)
    np.testing.assert_allclose(s.mass, 2000.0 * np.prod(s.hi - s.lo, axis=1))
    assert np.all(s.sph_material == 2)
    with pytest.raises(ConfigError, match="density"):
        build_building(cfg)


def test_blocks_thinner_than_two_radii_are_refused():
    with pytest.raises(ConfigError, match="thinner than two sphere radii"):
        build_building(build(StructureConfig, cfg_dict(wall_thickness=0.15)))


@pytest.mark.parametrize("data, words", [
    (dict(sigma_c=0.0, delta_f=0.02), "sigma_c"),
    (dict(sigma_c=1e7, delta_f=-0.02), "delta_f"),
    (dict(sigma_c=1e7, delta_f=0.02, mode="damaged"), "did you mean 'damage'"),
    (dict(sigma_c=1e7, delta_f=0.02, points_per_edge=0), "points_per_edge"),
])
def test_cohesive_config_errors(data, words):
    with pytest.raises(ConfigError, match=words):
        build(CohesiveConfig, data, "case.yaml", prefix="dem.cohesive")


def test_assemble_pair_shares_one_face():
    s = assemble([[0, 0, 0], [1, 0, 0]], [[1, 1, 1], [2, 1.5, 1]], density=1000.0, sphere_radius=0.1)
    assert len(s.faces) == 1
    f = s.faces[0]
    assert (f.a, f.b) == (0, 1) and f.normal == (1.0, 0.0, 0.0) and f.area == pytest.approx(1.0)


def test_docs_list_every_schema_field():
    """docs/cohesive.md carries the field tables of the three schema classes."""
    import dataclasses

    from fcm_fsi.config.structure import OpeningConfig
    text = (ROOT / "docs" / "cohesive.md").read_text()
    for cls, prefix in ((CohesiveConfig, "dem.cohesive"), (StructureConfig, "dem.structure"),
                        (OpeningConfig, "dem.structure.openings[]")):
        assert f"| key `{prefix}.…` |" in text
        for f in dataclasses.fields(cls):
            assert f"| `{f.name}` |" in text and f.metadata["doc"] in text, f.name


def dem_config(blocks, cohesive=True):
    from fcm_fsi.config.dem import DEMConfig
    data = dict(dt=1e-5, gravity=[0.0, -9.81, 0.0], blocks=blocks,
                materials=[dict(name="mortar", stiffness=1e6, restitution=0.2, friction_angle=30.0, density=2400.0)])
    if cohesive:
        data["cohesive"] = dict(sigma_c=1e5, delta_f=1e-3)
    return build(DEMConfig, data, "case.yaml", prefix="dem")


def brick(y, **kw):
    return dict(shape="box", material="mortar", position=[1.0, y, 0.0], size=[0.04, 0.05, 0.1], radius=0.005, **kw)


def test_bonded_blocks_are_bonded_on_their_shared_faces_only_and_start_stress_free():
    """``dem.blocks[].bonded``: a stack of three bonded bricks on a fixed bonded footing gets
    one bond per shared face (3), none to the touching unbonded brick on top; the built
    configuration carries no bond force."""
    from fcm_fsi.dem.model import build_system
    cfg = dem_config([brick(0.025, bonded=True, fixed=True), brick(0.075, bonded=True),
                      brick(0.125, bonded=True), brick(0.175, bonded=True), brick(0.225)])
    system = build_system(cfg, with_ledger=False)
    bonds = next(it for it in system.interactions if hasattr(it, "broken_bonds"))
    assert bonds.n_bonds == 3 and bonds.n_points == 3 * 4
    assert sorted(set(zip(bonds.pt_a.tolist(), bonds.pt_b.tolist()))) == [(0, 1), (1, 2), (2, 3)]
    np.testing.assert_allclose(bonds.bond_area, 0.04 * 0.1)
    st = system.state
    f, t = np.zeros((st.nb, 3)), np.zeros((st.nb, 3))
    bonds.compute(st.pos, st.quat, f, t)
    assert np.abs(f).max() < 1e-9 and np.abs(t).max() < 1e-12
    # pulled apart by more than δ_f, the bond between 2 and 3 breaks; the others hold
    pos = st.pos.copy()
    pos[3, 1] += 2e-3
    bonds.compute(pos, st.quat, f, t)
    assert bonds.broken_bonds().tolist() == [False, False, True]


@pytest.mark.parametrize("blocks, cohesive, words", [
    ([brick(0.025, bonded=True), brick(0.075, bonded=True)], False, "dem.cohesive"),
    ([brick(0.025, bonded=True, angle=30.0)], True, "bonded"),
    ([dict(shape="sphere", material="mortar", position=[0, 0, 0], radius=0.01, bonded=True)], True, "bonded"),
])
def test_bonded_block_config_errors(blocks, cohesive, words):
    with pytest.raises(ConfigError, match=words):
        dem_config(blocks, cohesive)


@pytest.mark.parametrize("name", ["tsunami_building", "building_paper"])
def test_shipped_buildings_start_standing_on_the_ground(name):
    """The structure's spheres are inset by one radius (their envelope is the box), so a
    building whose ``origin`` is on the ground plane starts touching it. The tsunami case had
    its origin one radius up (z = 0.1 m): the 72 t building fell 0.1 m at t = 0, hit the ground
    at 1.4 m/s and bounced until ≈ 0.6 s, just before the water arrived."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.dem.model import build_state, build_structure
    dem = load_case(ROOT / "cases" / f"{name}.yaml").dem
    st = build_state(dem, build_structure(dem))
    st.update_spheres()
    ground = [w for w in dem.walls if w.kind == "plane" and tuple(w.normal) == (0.0, 0.0, 1.0)]
    z_ground = ground[0].point[2] if ground else 0.0
    free = ~st.fixed[st.sph_block]                               # not the foundation under the ground
    lowest = float((st.sph_pos[free, 2] - st.sph_radius[free]).min())
    assert lowest == pytest.approx(z_ground, abs=1e-9)


def _one_bay_case(foundation: float) -> dict:
    """A one-storey, one-bay frame (columns and walls of 0.4 m, sphere r 0.1 m) on the ground."""
    return {"name": "frame", "run": {"t_end": 0.1, "dt": 0.01}, "dem": {
        "dt": 2.0e-5, "gravity": [0, 0, -9.81],
        "materials": [{"name": "c", "stiffness": 1.0e7, "restitution": 0.2, "friction_angle": 30.0,
                       "density": 2400.0}],
        "walls": [{"kind": "plane", "material": "c", "point": [0, 0, 0], "normal": [0, 0, 1]}],
        "cohesive": {"sigma_c": 1.0e7, "delta_f": 0.02},
        "structure": {"origin": [0.0, 0.0, 0.0], "storeys": 1, "storey_height": 1.2, "bays_x": [1.2],
                      "bays_y": [1.2], "column": [0.4, 0.4], "wall_thickness": 0.4, "slab_thickness": 0.4,
                      "block_size": 1.0, "sphere_radius": 0.1, "material": "c", "foundation": foundation}}}


def test_foundation_is_one_fixed_block_after_the_building_bonded_to_the_ground_floor():
    from fcm_fsi.config.case import case_from_dict
    from fcm_fsi.coupling.dem_side import shapes_of_blocks
    from fcm_fsi.dem.model import build_state, build_structure
    loose = build_structure(case_from_dict(_one_bay_case(0.0)).dem)
    dem = case_from_dict(_one_bay_case(0.4)).dem
    anchored = build_structure(dem)
    n = loose.nb
    assert anchored.nb == n + 1 and np.flatnonzero(anchored.fixed).tolist() == [n]
    assert np.array_equal(anchored.lo[:n], loose.lo) and np.array_equal(anchored.hi[:n], loose.hi)
    assert anchored.lo[n].tolist() == [-0.2, -0.2, -0.4] and anchored.hi[n].tolist() == [1.4, 1.4, 0.0]
    on_ground = set(np.flatnonzero(loose.lo[:, 2] == 0.0))
    to_foundation = {f.a if f.b == n else f.b for f in anchored.faces if n in (f.a, f.b)}
    assert on_ground and to_foundation == on_ground
    st = build_state(dem, anchored)
    assert st.fixed.tolist() == [False] * n + [True]
    assert n not in set(shapes_of_blocks(dem, st).body)          # under the ground: the fluid never sees it
    bad = _one_bay_case(0.1)
    with pytest.raises(ConfigError, match="structure.foundation.*two sphere radii"):
        case_from_dict(bad)


@pytest.mark.parametrize("foundation", [0.0, 0.4])
def test_a_lateral_load_above_friction_slides_a_loose_frame_but_not_an_anchored_one(foundation):
    """Push every block sideways with 0.8 × its weight (friction tan 30° = 0.58): a frame standing
    loose on the ground slides off (a ≈ (0.8 − 0.58) g ≈ 2.2 m/s², ≈ 1.1 cm in 0.1 s); bonded to
    its foundation, the joints carry the base shear and it barely moves (elastic, sub-mm)."""
    from fcm_fsi.config.case import case_from_dict
    from fcm_fsi.dem.model import build_system
    system = build_system(case_from_dict(_one_bay_case(foundation)).dem, with_ledger=False)
    st = system.state
    free = ~st.fixed
    system.run(200)                                   # settle the contacts (4 ms)
    x0 = st.pos[free, 0].copy()
    st.ext_force[free, 0] = 0.8 * 9.81 * st.mass[free]
    system.run(5000)                                  # 0.1 s
    slide = float(np.mean(st.pos[free, 0] - x0))
    if foundation == 0.0:
        assert 0.5 * 0.011 < slide < 2.0 * 0.011
    else:
        assert abs(slide) < 1e-3


def test_member_names_follow_the_blocks_and_the_sequence_orders_members_by_first_break(paper):
    from fcm_fsi.dem.failure_sequence import failure_sequence, member_names
    cfg, _, s = paper
    names = member_names(cfg)
    assert len(names) == s.nb
    front = [i for i, n in enumerate(names) if n == "wall xmin s0"]
    back = [i for i, n in enumerate(names) if n == "wall xmax s1"]
    # every front-wall block lies in the x-min wall of the ground floor, every back one in x-max upstairs
    assert front and np.allclose(s.pos[front, 0], cfg.origin[0])
    assert np.all(s.pos[front, 2] < cfg.storey_height)
    assert back and np.allclose(s.pos[back, 0], cfg.origin[0] + sum(cfg.bays_x))
    assert np.all(s.pos[back, 2] > cfg.storey_height)
    mass = {n: s.mass[[i for i, m in enumerate(names) if m == n]].sum() for n in ("wall xmin s0", "wall xmax s0")}
    assert mass["wall xmin s0"] < mass["wall xmax s0"]   # the door
    col = names.index("column s0")
    # two breaks at 1.0 s (front–column, front–front), one at 2.0 s (back–back), one outside
    # the structure (block 0 is a loose block before it, named as block_members names it)
    t = np.array([2.0, 1.0, 1.0, 3.0])
    a = np.array([back[0] + 1, front[0] + 1, front[1] + 1, 0])
    b = np.array([back[1] + 1, col + 1, front[2] + 1, 0])
    seq = failure_sequence(t, a, b, ["block 0"] + names)
    assert [(f.member, f.first_break, f.bonds) for f in seq] == [
        ("column s0", 1.0, 1), ("wall xmin s0", 1.0, 2), ("wall xmax s1", 2.0, 1), ("block 0", 3.0, 1)]


def test_failure_sequence_cli_reads_a_run_folder_and_the_back_wall_rule(tmp_path, capsys):
    import shutil

    from fcm_fsi.cli import main
    from fcm_fsi.dem.failure_sequence import MemberFailure
    from fcm_fsi.verify.cases.tsunami import back_wall_after_front
    shutil.copy(ROOT / "cases" / "tsunami_building.yaml", tmp_path / "case.resolved.yaml")
    (tmp_path / "bond_breaks.csv").write_text("t [s],bond [-],block_a [-],block_b [-]\n"
                                              "1.5,3.0,208.0,16.0\n1.25,7.0,32.0,33.0\n")
    assert main(["failure-sequence", str(tmp_path)]) == 0
    rows = [(ln[:18].strip(), float(ln.split()[-3]), int(ln.split()[-1]))
            for ln in capsys.readouterr().out.splitlines()[1:]]
    # storey 0 lists its 16 column blocks first, then its walls in the case's order (xmin, xmax,
    # ...) of 12 blocks each: block 16 is the front wall's first, 32 and 33 the back wall's;
    # 208 the foundation. Ties in time are ordered by name.
    assert rows == [("wall xmax s0", 1.25, 1), ("foundation", 1.5, 1), ("wall xmin s0", 1.5, 1)]
    (tmp_path / "bond_breaks.csv").write_text("t [s],bond [-],block_a [-],block_b [-]\n")
    assert main(["failure-sequence", str(tmp_path)]) == 0 and "no bond broke" in capsys.readouterr().out
    assert main(["failure-sequence", str(tmp_path / "nowhere")]) == 2 and "case.resolved.yaml" in capsys.readouterr().err
    def seq(*mt):
        return [MemberFailure(m, t, 1, t) for m, t in mt]
    assert back_wall_after_front(seq(("wall xmin s0", 1.0), ("wall xmax s0", 2.0))) == 1.0
    assert back_wall_after_front(seq(("wall xmax s1", 0.5), ("wall xmin s0", 1.0))) == 0.0
    assert back_wall_after_front(seq(("wall xmin s0", 1.0), ("column s0", 2.0))) == 0.0
    assert np.isnan(back_wall_after_front(seq(("wall xmax s0", 1.0))))


def test_front_wall_fails_first_names_the_members_of_the_first_breaking_step():
    from fcm_fsi.config import load_case
    from fcm_fsi.dem.failure_sequence import block_members
    from fcm_fsi.verify.cases.tsunami import front_wall_first
    members = block_members(load_case(ROOT / "cases" / "tsunami_building.yaml"))
    assert len(members) == 208 + len([m for m in members if m == "foundation"])
    # the order of the CLI test above: block 16 is the front wall's first, 32 the back wall's,
    # 0 a ground-floor column, 208 the foundation
    assert (members[16], members[32], members[0], members[208]) == ("wall xmin s0", "wall xmax s0", "column s0",
                                                                    "foundation")
    assert front_wall_first(np.array([[16, 208], [17, 16]]), members) == 1.0
    assert front_wall_first(np.array([[16, 208], [0, 208]]), members) == 0.0   # a column joint too
    assert front_wall_first(np.array([[32, 33]]), members) == 0.0
    assert np.isnan(front_wall_first(np.zeros((0, 2), int), members))


def test_back_wall_peak_traction_reads_the_back_walls_largest_lambda_from_a_checkpoint(tmp_path, capsys):
    """``back_wall_peak_traction`` (verify tsunami_building): eq 28 at the largest λ_max of the
    bond points touching an x-max wall block (foundation joints included), capped at 1 past the
    peak and 1 for a broken point; loads elsewhere do not count; another structure's checkpoint
    is refused."""
    import h5py

    from fcm_fsi.config import load_case
    from fcm_fsi.config.loader import ConfigError
    from fcm_fsi.dem.bond_report import bonded_structure_of, member_peak_traction
    from fcm_fsi.dem.cohesive import shape_g
    from fcm_fsi.dem.failure_sequence import block_members
    from fcm_fsi.verify.cases.tsunami import back_wall_peak_traction
    case = load_case(ROOT / "cases" / "tsunami_building.yaml")
    members = block_members(case)
    _, bonds = bonded_structure_of(case, with_ledger=False)
    back = {k for k, m in enumerate(members) if m.startswith("wall xmax")}
    touches = np.array([a in back or b in back for a, b in zip(bonds.pt_a, bonds.pt_b)])
    to_foundation = np.flatnonzero(touches & ((bonds.pt_a == 208) | (bonds.pt_b == 208)))
    elsewhere = np.flatnonzero(~touches)
    assert to_foundation.size and elsewhere.size
    lam = np.zeros(bonds.n_points)
    broken = np.zeros(bonds.n_points, bool)
    lam[elsewhere[0]], broken[elsewhere[1]] = 0.9, True      # the front wall may break: not counted
    lam[to_foundation[0]] = 0.2
    ck = tmp_path / "checkpoint.h5"

    def write():
        with h5py.File(ck, "w") as f:
            f["globals/dem_int2__bond_lam_max"] = lam
            f["globals/dem_int2__bond_broken"] = broken
    write()
    assert back_wall_peak_traction(case, ck, members) == pytest.approx(float(shape_g(0.2)))
    lam[to_foundation[1]] = 0.6                                # past the peak: its strength was reached
    write()
    assert back_wall_peak_traction(case, ck, members) == pytest.approx(1.0)
    lam[to_foundation[1]] = 0.0
    broken[to_foundation[1]] = True
    write()
    assert back_wall_peak_traction(case, ck, members) == pytest.approx(1.0)
    assert np.isnan(back_wall_peak_traction(case, tmp_path / "none.h5", members))
    # the CLI's per-member table: the same numbers, most loaded first
    from fcm_fsi.cli import main
    lam[to_foundation[1]], broken[to_foundation[1]] = 0.0, False
    write()
    assert main(["bond-report", str(ROOT / "cases" / "tsunami_building.yaml"), str(ck), "--top", "1", "--members"]) == 0
    out = capsys.readouterr().out.splitlines()
    table = {ln[:16].strip(): float(ln.split()[-1]) for ln in out[out.index("member            largest traction/σ_c") + 1:]}
    assert table["wall xmax s0"] == pytest.approx(float(shape_g(0.2)), abs=1e-3)
    assert list(table.values()) == sorted(table.values(), reverse=True)
    assert main(["bond-report", str(ROOT / "cases" / "bonded_wall_surge.yaml"), str(ck), "--members"]) == 2
    assert "error:" in capsys.readouterr().err
    assert np.isnan(member_peak_traction(bonds, lam, broken, members, "wall ymid"))
    with pytest.raises(ConfigError, match="not this case's checkpoint"):
        member_peak_traction(bonds, lam[:-1], broken[:-1], members, "wall xmax")
