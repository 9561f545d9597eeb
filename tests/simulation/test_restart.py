"""Checkpoint/restart: 2N steps equal N steps + restart + N steps, on 1 and on 2 ranks."""
from __future__ import annotations

import logging
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from tests.conftest import run_cli, run_half_and_resume

CASE = {"name": "restart", "run": {"t_end": 0.4, "dt": 0.02, "checkpoint_every": 10, "log_every": 5},
        "mesh": {"kind": "rectangle", "lower": [-1, -1], "upper": [1, 1], "cells": [24, 24]},
        "phase_field": {"width_factor": 1.0, "supg": False, "volume_correction": True,
                        "initial": {"shape": "circle", "center": [0.0, 0.4], "radius": 0.3},
                        "velocity": {"kind": "rotation"}}}


def final_phi(path) -> tuple[np.ndarray, np.ndarray]:
    """(node coordinates, φ) of a checkpoint; the node order depends on the partition."""
    with h5py.File(path, "r") as f:
        return f["fields/phi/coords"][...], f["fields/phi/values"][...]


def max_difference(a, b) -> float:
    """max |φ_a − φ_b| over nodes matched by coordinates (they agree to ~1e-16 m)."""
    from scipy.spatial import cKDTree
    dist, idx = cKDTree(b[0]).query(a[0])
    assert dist.max() < 1e-12
    return float(np.abs(a[1] - b[1][idx]).max())


@pytest.mark.parametrize("np_", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_restart_reproduces_uninterrupted_run(tmp_path, np_):
    case = tmp_path / "case.yaml"
    case.write_text(yaml.safe_dump(CASE))
    full = run_cli([str(case), "--output", str(tmp_path / "full")], np_)
    assert full.returncode == 0, full.stderr
    run_half_and_resume(case, tmp_path / "half", 0.2, np_)
    a, b = final_phi(tmp_path / "full" / "checkpoint.h5"), final_phi(tmp_path / "half" / "checkpoint.h5")
    # φ is solved by GMRES to rtol 1e-12 with a partition-dependent block-Jacobi/ILU
    # preconditioner (the partition of a new run may differ): agreement to solver tolerance
    assert max_difference(a, b) < 1e-10
    series = np.genfromtxt(tmp_path / "half" / "series.csv", delimiter=",", skip_header=1)
    assert series.shape[0] == 21  # t = 0 plus 20 steps, continued across the restart
    assert (tmp_path / "full" / "fields.xdmf").exists() and (tmp_path / "full" / "case.resolved.yaml").exists()


def test_restart_refuses_changed_case_or_rank_count(tmp_path):
    case = tmp_path / "case.yaml"
    case.write_text(yaml.safe_dump(CASE))
    assert run_cli([str(case), "--output", str(tmp_path / "a"), "--set", "run.t_end=0.04"]).returncode == 0
    ck = str(tmp_path / "a" / "checkpoint.h5")
    res = run_cli([str(case), "--output", str(tmp_path / "a"), "--restart", ck, "--set", "phase_field.width_factor=2"])
    assert res.returncode == 2 and "the case changed" in res.stderr and "Traceback" not in res.stderr
    res = run_cli([str(case), "--output", str(tmp_path / "a"), "--restart", ck], np_=2)
    assert res.returncode == 2 and "written by 1 rank(s)" in res.stderr
    res = run_cli([str(case), "--restart", str(tmp_path / "nope.h5")])
    assert res.returncode == 2 and "checkpoint file not found" in res.stderr


@pytest.mark.mpi
def test_one_and_two_ranks_agree(tmp_path):
    """The same case on 1 and 2 ranks: identical diagnostics to solver tolerance."""
    case = tmp_path / "case.yaml"
    data = dict(CASE, run=dict(CASE["run"], t_end=0.2))
    case.write_text(yaml.safe_dump(data))
    for n in (1, 2):
        assert run_cli([str(case), "--output", str(tmp_path / f"r{n}")], n).returncode == 0
    s1 = np.genfromtxt(tmp_path / "r1" / "series.csv", delimiter=",", skip_header=1)
    s2 = np.genfromtxt(tmp_path / "r2" / "series.csv", delimiter=",", skip_header=1)
    np.testing.assert_allclose(s1[:, :-1], s2[:, :-1], rtol=1e-9, atol=1e-12)


def test_single_phase_fluid_case_runs_and_restarts(tmp_path, root):
    """cases/cavity_re100.yaml through the CLI: 2 steps = 1 step + restart + 1 step."""
    case = str(root / "cases" / "cavity_re100.yaml")
    small = ["--set", "mesh.cells=[16,16]"]
    full = run_cli([case, "--output", str(tmp_path / "full"), "--set", "run.t_end=4.0", *small])
    assert full.returncode == 0, full.stderr
    half = run_cli([case, "--output", str(tmp_path / "half"), "--set", "run.t_end=2.0", *small])
    assert half.returncode == 0, half.stderr
    resumed = run_cli([case, "--output", str(tmp_path / "half"), "--set", "run.t_end=4.0", *small,
                       "--restart", str(tmp_path / "half" / "checkpoint.h5")])
    assert resumed.returncode == 0, resumed.stderr
    a = np.genfromtxt(tmp_path / "full" / "series.csv", delimiter=",", skip_header=1)
    b = np.genfromtxt(tmp_path / "half" / "series.csv", delimiter=",", skip_header=1)
    assert a.shape == b.shape == (3, 8)
    np.testing.assert_allclose(a[-1, :7], b[-1, :7], rtol=1e-10)


def test_a_failed_solve_stops_the_run_with_a_message_not_a_traceback(tmp_path, caplog):
    """A linear (or nonlinear) solve that fails inside a step reaches the user as
    SimulationDiverged naming the step, the time and the last good checkpoint — the CLI's
    'run stopped' message — not as a PETSc traceback."""
    from mpi4py import MPI

    from fcm_fsi.config.case import load_case
    from fcm_fsi.fluid.solvers import LinearSolveError
    from fcm_fsi.simulation.loop import SimulationDiverged, TimeLoop
    root = Path(__file__).resolve().parents[2]
    case = load_case(root / "cases" / "still_water.yaml", ["output.xdmf=false", "output.checkpoint=false"])
    caplog.set_level(logging.INFO, logger="fcm_fsi")
    logger = logging.getLogger("fcm_fsi")      # does not propagate once setup_logging ran in this process
    logger.addHandler(caplog.handler)

    class FailingModel:
        mesh, output_functions, series_units = None, [], {}

        def diagnostics(self):
            return {}

        def stable_dt(self, cfl):
            return float("inf")

        def health(self, diag):
            return None

        def advance(self, t, dt, timer):
            raise LinearSolveError("linear solve ns_ diverged at step 1 (t = 0.002 s): reason -11")

    with pytest.raises(SimulationDiverged, match=r"step 1, t = 0 s .*reason -11; last good checkpoint: .*checkpoint.h5"):
        TimeLoop(case, FailingModel(), tmp_path, MPI.COMM_WORLD, None).run()
    # the cost so far is still reported (a diverged run used to end without its timing table)
    logger.removeHandler(caplog.handler)
    assert "stopped still_water after 0 steps" in caplog.text and "peak memory (max RSS)" in caplog.text


def test_fingerprint_ignores_the_solver_choice_but_not_the_physics(root):
    """A restart may switch the linear solver (e.g. to LU after ILU-GMRES broke down), which
    changes the solution only at solver tolerance; a physical parameter may not change."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import case_fingerprint
    path = root / "cases" / "dam_break.yaml"
    base = case_fingerprint(load_case(path))
    solver = ['fluid.petsc={"ksp_type": "gmres", "pc_type": "lu"}', "fluid.reuse_preconditioner=true",
              'phase_field.petsc={"ksp_type": "preonly", "pc_type": "lu"}', "run.t_end=9.0", "fluid.krylov_start=zero"]
    assert case_fingerprint(load_case(path, solver)) == base
    # the gas's Courant bound may be loosened on restart; the liquid's may not
    assert case_fingerprint(load_case(path, ["run.cfl_gas=1.5"])) == base
    assert case_fingerprint(load_case(path, ["run.cfl=0.3"])) != base
    assert case_fingerprint(load_case(path, ["fluid.density=1000.5"])) != base
    assert case_fingerprint(load_case(path, ["fluid.rtol=1e-6"])) != base
    # so may the update between the coupling's passes; the coupling's physics may not
    tsunami = root / "cases" / "tsunami_building.yaml"
    base_t = case_fingerprint(load_case(tsunami))
    assert case_fingerprint(load_case(tsunami, ["coupling.iteration_method=aitken"])) == base_t
    assert case_fingerprint(load_case(tsunami, ["coupling.cut_extension=100"])) != base_t
    # checkpoints written before (their hash covered the solver options) are still accepted
    legacy = case_fingerprint(load_case(path), legacy=True)
    assert legacy != base and case_fingerprint(load_case(path, solver[:1]), legacy=True) != legacy


def test_a_section_added_later_leaves_the_fingerprint_of_cases_without_it(root, monkeypatch):
    """Checkpoints written before the ``pd`` section existed still restart: a case without it
    hashes as if the section did not exist in the schema."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.io import checkpoint
    case = load_case(root / "cases" / "block_overturn.yaml")
    now = checkpoint.case_fingerprint(case)
    schema_before = checkpoint.to_dict

    def without_pd(c):
        data = schema_before(c)
        assert "pd" in data and data["pd"] is None
        del data["pd"]
        return data

    monkeypatch.setattr(checkpoint, "to_dict", without_pd)
    assert checkpoint.case_fingerprint(case) == now


def test_a_checkpoint_is_accepted_under_any_of_the_given_fingerprints(tmp_path):
    from mpi4py import MPI

    from fcm_fsi.config.loader import ConfigError
    from fcm_fsi.io.checkpoint import read_checkpoint, write_checkpoint
    ck = tmp_path / "c.h5"
    write_checkpoint(ck, MPI.COMM_WORLD, "old-hash", 3, 0.5, 0.1, {}, {"x": np.arange(3.0)})
    assert read_checkpoint(ck, MPI.COMM_WORLD, ("new-hash", "old-hash")).step == 3
    with pytest.raises(ConfigError, match="the case changed"):
        read_checkpoint(ck, MPI.COMM_WORLD, "new-hash")


def test_the_replaced_checkpoint_is_kept_one_interval_back(tmp_path):
    """A block kicked by one bad step must be continuable from before the kick, which the
    newest checkpoint, written after it, cannot do: the replaced file is kept."""
    from mpi4py import MPI

    from fcm_fsi.io.checkpoint import previous_checkpoint, read_checkpoint, write_checkpoint
    ck = tmp_path / "checkpoint.h5"
    assert previous_checkpoint(ck) == tmp_path / "checkpoint.previous.h5"
    for step in (250, 500, 750):
        write_checkpoint(ck, MPI.COMM_WORLD, "hash", step, step * 1e-3, 1e-3, {}, {"x": np.full(2, step)})
    assert read_checkpoint(ck, MPI.COMM_WORLD, "hash").step == 750
    earlier = read_checkpoint(previous_checkpoint(ck), MPI.COMM_WORLD, "hash")
    assert earlier.step == 500 and np.all(earlier.globals["x"] == 500)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.h5", "checkpoint.previous.h5"]


def test_series_csv_resumes_at_the_checkpoint_time(tmp_path):
    """A restart keeps the rows up to the checkpoint and drops those an earlier run wrote
    after it before stopping (they are computed again); a lazy series is created at its
    first row or at close, so its owner can learn of the restart after building it."""
    from fcm_fsi.io.csv import TimeSeriesCSV
    path = tmp_path / "s.csv"
    first = TimeSeriesCSV(path, {"step": "-", "t": "s", "x": "m"})
    for k in range(6):
        first.write(step=k, t=0.1 * k, x=k * k)
    first.close()
    again = TimeSeriesCSV(path, {"step": "-", "t": "s", "x": "m"}, append=True, resume_at=0.3)
    again.write(step=4, t=0.4, x=-1.0)
    again.close()
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_allclose(rows[:, 1], [0.0, 0.1, 0.2, 0.3, 0.4])
    assert rows[-1, 2] == -1.0 and path.read_text().startswith("step [-],t [s],x [m]\n")
    lazy = TimeSeriesCSV(path, {"step": "-", "t": "s", "x": "m"}, lazy=True)
    lazy.resume(0.1)
    lazy.write(step=2, t=0.2, x=7.0)
    np.testing.assert_allclose(np.loadtxt(path, delimiter=",", skiprows=1)[:, 2], [0.0, 1.0, 7.0])
    empty = TimeSeriesCSV(tmp_path / "e.csv", {"t": "s"}, lazy=True)
    assert not (tmp_path / "e.csv").exists()
    empty.close()
    assert (tmp_path / "e.csv").read_text() == "t [s]\n"
    empty.write(t=1.0)                                    # after close: ignored, not a new file
    assert (tmp_path / "e.csv").read_text() == "t [s]\n"


def test_checkpoints_of_code_before_an_option_existed_are_accepted_only_at_its_old_value(root):
    """Options added later (coupling.load_split, then coupling.wall_motion) were not in the hash
    of older checkpoints: such a checkpoint (hashed without the options added after it) is
    accepted while the case keeps those options at the values that do what the older code
    did, and refused once one of them changes the physics."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import ADDED_OPTIONS, accepted_fingerprints, case_fingerprint
    path = root / "cases" / "block_overturn.yaml"
    old_mass = ["coupling.added_mass_model=volume"]   # the case itself uses the flow's
    owner = load_case(path, old_mass)
    keys = [(sec, key) for sec, key, _ in ADDED_OPTIONS]
    assert keys[:2] == [("coupling", "load_split"), ("coupling", "wall_motion")]
    accepted = accepted_fingerprints(owner)
    assert accepted[0] == case_fingerprint(owner)
    for k in range(len(keys)):
        before = tuple(keys[k:])          # a checkpoint from before option k existed
        for legacy in (False, True):
            assert case_fingerprint(owner, legacy, before) in accepted
    # a hash missing only an older option is no state any code wrote
    assert case_fingerprint(owner, without=(keys[0],)) not in accepted
    shared = load_case(path, ["coupling.load_split=shared"] + old_mass)
    assert case_fingerprint(shared, without=tuple(keys)) not in accepted_fingerprints(shared)
    assert case_fingerprint(shared, without=tuple(keys[1:])) in accepted_fingerprints(shared)
    cluster = load_case(path, ["coupling.wall_motion=bonded_cluster"] + old_mass)
    assert case_fingerprint(cluster, without=tuple(keys[1:])) not in accepted_fingerprints(cluster)
    assert case_fingerprint(cluster, without=tuple(keys)) not in accepted_fingerprints(cluster)
    # only the code from wall_motion on (with and without each of the later options) wrote it,
    # with the boundaries named by axis or by their former names
    expected = []
    for k in range(len(keys), 1, -1):
        expected += [case_fingerprint(cluster, legacy, tuple(keys[k:]), former_names)
                     for former_names, legacy in ((False, False), (False, True), (True, False), (True, True))]
    # (an option the case has no section for, such as dem.structure.foundation here, leaves the
    # hash as it is: the same fingerprint once)
    assert accepted_fingerprints(cluster) == tuple(dict.fromkeys(expected))


def test_a_checkpoint_from_before_the_boundaries_were_named_by_axis_is_accepted(root):
    """A checkpoint hashed with the boundaries' former names (left … back, as the code before
    the axis names loaded the case) is accepted by the converted case; one whose names put the
    conditions on other planes is not."""
    import dataclasses

    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import accepted_fingerprints, case_fingerprint
    case = load_case(root / "cases" / "impact_box_3d.yaml")     # slip sides and ground, open top

    def named(names: dict):
        """The case with its boundaries renamed (bypassing the check that refuses former names)."""
        old = dataclasses.replace(case)
        bcs = tuple(dataclasses.replace(bc, boundary=names[bc.boundary]) for bc in case.fluid.boundaries)
        object.__setattr__(old, "fluid", dataclasses.replace(case.fluid, boundaries=bcs))
        return old
    former = {"xmin": "left", "xmax": "right", "ymin": "bottom", "ymax": "top", "zmin": "front", "zmax": "back"}
    before = case_fingerprint(named(former))
    assert before != case_fingerprint(case)
    assert before == case_fingerprint(case, former_names=True) and before in accepted_fingerprints(case)
    lid_below = {**former, "zmin": "back", "zmax": "front"}     # the open plane at the ground
    assert case_fingerprint(named(lid_below)) not in accepted_fingerprints(case)


def test_a_checkpoint_from_before_blocks_could_be_bonded_is_accepted_while_none_is(root):
    """``dem.blocks[].bonded`` sits in every block: a checkpoint hashed without it
    is accepted while no block is bonded (block_overturn), and refused once one is
    (bonded_wall_surge)."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import ADDED_OPTIONS, accepted_fingerprints, case_fingerprint
    keys = [(sec, key) for sec, key, _ in ADDED_OPTIONS]
    before = tuple(keys[keys.index(("dem.blocks[]", "bonded")):])
    plain = load_case(root / "cases" / "block_overturn.yaml", ["coupling.added_mass_model=volume"])
    old = case_fingerprint(plain, without=before)
    assert old != case_fingerprint(plain) and old in accepted_fingerprints(plain)
    bonded = load_case(root / "cases" / "bonded_wall_surge.yaml")
    assert any(b.bonded for b in bonded.dem.blocks)
    assert case_fingerprint(bonded, without=before) not in accepted_fingerprints(bonded)


def test_a_checkpoint_from_before_foundations_is_accepted_only_for_a_loose_building(root):
    """``dem.structure.foundation``: a tsunami checkpoint hashed without it is
    accepted while the building has none, and refused once it stands on one."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import ADDED_OPTIONS, accepted_fingerprints, case_fingerprint
    keys = [(sec, key) for sec, key, _ in ADDED_OPTIONS]
    before = tuple(keys[keys.index(("dem.structure", "foundation")):])
    path = root / "cases" / "tsunami_building.yaml"
    founded = load_case(path)
    assert founded.dem.structure.foundation > 0
    assert case_fingerprint(founded, without=before) not in accepted_fingerprints(founded)
    loose = load_case(path, ["dem.structure.foundation=0", "fluid.mass_consistent_convection=false",
                             "coupling.unresolved_cells=0"])
    old = case_fingerprint(loose, without=before)
    assert old != case_fingerprint(loose) and old in accepted_fingerprints(loose)


def test_a_checkpoint_from_before_the_mass_defect_term_is_refused_once_the_term_is_on(root):
    """``fluid.mass_consistent_convection`` changes the momentum equation: a
    checkpoint hashed without it is accepted only while the case keeps it off."""
    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import ADDED_OPTIONS, accepted_fingerprints, case_fingerprint
    keys = [(sec, key) for sec, key, _ in ADDED_OPTIONS]
    before = tuple(keys[keys.index(("fluid", "mass_consistent_convection")):])
    path = root / "cases" / "tsunami_building.yaml"
    on = load_case(path)
    assert on.fluid.mass_consistent_convection
    assert case_fingerprint(on, without=before) not in accepted_fingerprints(on)
    off = load_case(path, ["fluid.mass_consistent_convection=false", "coupling.unresolved_cells=0"])
    old = case_fingerprint(off, without=before)
    assert old != case_fingerprint(off) and old in accepted_fingerprints(off)


def test_verify_resume_reads_a_finished_run_instead_of_running_it_again(root, tmp_path):
    """``verify --resume``: a run whose checkpoint is this case's and at its t_end is read, on
    any rank count (block_overturn's 15° run on 2 ranks after the others ran on 1 each); one
    stopped earlier, or of another case, is not."""
    from mpi4py import MPI

    from fcm_fsi.config.case import load_case
    from fcm_fsi.io.checkpoint import case_fingerprint, write_checkpoint
    from fcm_fsi.verify.cases.coupled import finished
    case = load_case(root / "cases" / "block_overturn.yaml")
    ck = tmp_path / "checkpoint.h5"
    comm = MPI.COMM_WORLD
    for t, fingerprint, expected in ((case.run.t_end, case_fingerprint(case), True),
                                     (0.5 * case.run.t_end, case_fingerprint(case), False),
                                     (case.run.t_end, "another case", False)):
        write_checkpoint(ck, comm, fingerprint, 10, t, 1e-3, {}, {})
        assert finished(str(ck), case, comm) is expected
    assert finished(str(tmp_path / "missing.h5"), case, comm) is False


KILLED_WRITER = """
import os, signal, sys
from pathlib import Path
from mpi4py import MPI
from dolfinx import fem, mesh
from fcm_fsi.io.fields import FieldWriter
msh = mesh.create_unit_square(MPI.COMM_WORLD, 16, 16)
phi = fem.Function(fem.FunctionSpace(msh, ("CG", 1)), name="phi")
writer = FieldWriter(Path(sys.argv[1]), msh, [phi])
for k in range(3):
    phi.x.array[:] = k
    writer.write(0.1 * k)
os.kill(os.getpid(), signal.SIGKILL)     # a crash: no close, no atexit
"""


def test_field_output_of_a_killed_run_stays_readable(tmp_path):
    """A run killed between outputs (SIGKILL, nothing closed) keeps every completed output
    time readable in fields.h5 and listed in fields.xdmf (before: the open HDF5 file was
    unreadable as a whole after a kill)."""
    import subprocess
    import sys
    script = tmp_path / "writer.py"
    script.write_text(KILLED_WRITER)
    proc = subprocess.run([sys.executable, str(script), str(tmp_path / "fields.xdmf")], capture_output=True)
    assert proc.returncode == -9, proc.stderr.decode()[-2000:]
    with h5py.File(tmp_path / "fields.h5", "r") as f:
        times = sorted(f["Function/phi"].keys())
        last = f["Function/phi"][times[-1]][...]
    assert len(times) == 3
    assert np.allclose(last, 2.0, rtol=0, atol=1e-12)
    assert (tmp_path / "fields.xdmf").read_text().count("<Time") == 3


@pytest.mark.mpi
def test_stop_file_ends_the_run_with_a_checkpoint_that_continues_it(tmp_path):
    """A STOP file in the output folder ends the run after the current step on every rank
    (exit 4, a message naming the checkpoint), with a checkpoint at that step and the file
    removed; --restart from it then reaches the uninterrupted run's end state."""
    case = tmp_path / "case.yaml"
    data = dict(CASE, run=dict(CASE["run"], t_end=0.1))
    case.write_text(yaml.safe_dump(data))
    full = run_cli([str(case), "--output", str(tmp_path / "full")], 2)
    assert full.returncode == 0, full.stderr
    out = tmp_path / "stopped"
    out.mkdir()
    (out / "STOP").touch()
    stopped = run_cli([str(case), "--output", str(out)], 2)
    assert stopped.returncode == 4, stopped.stderr
    said = stopped.stdout + stopped.stderr
    assert "stopped on request" in said and "--restart" in said
    assert "Traceback" not in stopped.stderr
    assert not (out / "STOP").exists()
    with h5py.File(out / "checkpoint.h5", "r") as f:
        assert int(f.attrs["step"]) == 1
    resumed = run_cli([str(case), "--output", str(out), "--restart", str(out / "checkpoint.h5")], 2)
    assert resumed.returncode == 0, resumed.stderr
    assert max_difference(final_phi(tmp_path / "full" / "checkpoint.h5"), final_phi(out / "checkpoint.h5")) < 1e-10
    series = np.genfromtxt(out / "series.csv", delimiter=",", skip_header=1)
    assert series.shape[0] == 6            # t = 0 and 5 steps, none repeated or lost


def test_sigterm_ends_the_run_after_its_step_with_a_checkpoint(tmp_path):
    """SIGTERM (a batch system's time limit, `kill`) mid-run: the step in progress completes,
    a checkpoint is written at it, exit code 4."""
    import signal
    import subprocess
    import sys
    import time

    from tests.conftest import ROOT, mpi_env
    case = tmp_path / "case.yaml"
    data = dict(CASE, run=dict(CASE["run"], t_end=200.0, checkpoint_every=100000, log_every=1000))
    case.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "fcm_fsi", str(case), "--output", str(out)], cwd=ROOT,
                            env=mpi_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 300
    while time.time() < deadline:          # wait for a few steps in the series
        rows = (out / "series.csv").read_text().count("\n") if (out / "series.csv").exists() else 0
        if rows >= 4 or proc.poll() is not None:
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    log, err = proc.communicate(timeout=300)
    assert proc.returncode == 4, err[-3000:]
    assert "stopped on request (a signal" in log + err
    with h5py.File(out / "checkpoint.h5", "r") as f:
        step = int(f.attrs["step"])
    series = np.genfromtxt(out / "series.csv", delimiter=",", skip_header=1)
    assert step >= 3 and series.shape[0] == step + 1


def test_shared_stop_file_stops_each_run_of_a_set_and_stays(tmp_path):
    """The verification runner's case-folder STOP (``shared_stop``) stops a run after its
    first step with a checkpoint, and is left in place so the set's next run stops too."""
    from mpi4py import MPI

    from fcm_fsi.config import case_from_dict
    from fcm_fsi.simulation.loop import StopRequested, TimeLoop
    from fcm_fsi.simulation.phase_field import PhaseFieldModel
    shared = tmp_path / "STOP"
    shared.touch()
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        case = case_from_dict(dict(CASE, name=name, run=dict(CASE["run"], t_end=0.1)))
        loop = TimeLoop(case, PhaseFieldModel(case, MPI.COMM_WORLD), tmp_path / name, MPI.COMM_WORLD,
                        restart=None, shared_stop=shared)
        with pytest.raises(StopRequested, match="STOP"):
            loop.run()
        assert loop.step == 1 and (tmp_path / name / "checkpoint.h5").exists()
    assert shared.exists()


def test_dt_growth_limits_the_adapted_step_to_a_factor_of_the_last():
    """run.dt_growth: from rest the CFL rule alone would jump to dt_max; with the limit the step
    grows by at most the factor per step, and a falling CFL step is never held up."""
    from fcm_fsi.config.case import case_from_dict
    from fcm_fsi.config.loader import ConfigError
    from fcm_fsi.simulation.loop import next_dt

    class Model:
        def __init__(self, dt):
            self.dt = dt

        def stable_dt(self, cfl):
            return self.dt

    data = {"name": "x", "run": {"t_end": 1.0, "dt": 1e-3, "cfl": 1.0, "dt_max": 0.01},
            "mesh": {"kind": "rectangle"}, "fluid": {}}
    free = case_from_dict(data)
    data["run"]["dt_growth"] = 1.2
    limited = case_from_dict(data)
    at_rest = Model(np.inf)
    assert next_dt(free, at_rest, 0.0, 1e-3) == pytest.approx(0.01)
    assert next_dt(limited, at_rest, 0.0, 1e-3) == pytest.approx(1.2e-3)
    assert next_dt(limited, Model(5e-4), 0.0, 1e-3) == pytest.approx(5e-4)
    with pytest.raises(ConfigError, match="run.dt_growth"):
        case_from_dict({**data, "run": {**data["run"], "dt_growth": 0.5}})


def test_a_failed_two_phase_step_is_retaken_as_two_half_steps(tmp_path):
    """The loop retakes a failed step of any model that can restore it (here the two-phase flow of
    still_water): the step's start state comes back and two half steps reach the same time; the
    series counts the retaken step."""
    from mpi4py import MPI

    from fcm_fsi.config.case import load_case
    from fcm_fsi.fluid.navier_stokes import NonlinearSolveError
    from fcm_fsi.simulation.loop import TimeLoop
    from fcm_fsi.simulation.two_phase import TwoPhaseModel
    root = Path(__file__).resolve().parents[2]
    case = load_case(root / "cases" / "still_water.yaml", ["output.xdmf=false", "output.checkpoint=false",
                                                           "run.cfl=null", "run.dt=0.01", "run.t_end=0.03"])
    model = TwoPhaseModel(case, MPI.COMM_WORLD)
    real, calls = model.ns.step, []

    def failing_second_step(**kw):
        calls.append(float(model.ns.dt.value))
        if len(calls) == 2:
            real(**kw)                               # leave a half-updated state behind
            raise NonlinearSolveError(2, 0.004, [1.0], "injected failure")
        return real(**kw)
    model.ns.step = failing_second_step
    TimeLoop(case, model, tmp_path, MPI.COMM_WORLD, None).run()
    assert calls == pytest.approx([0.01, 0.01, 0.005, 0.005, 0.01])
    assert model.ns.t == pytest.approx(0.03) and model.ns.step_count == 4
    series = np.genfromtxt(tmp_path / "series.csv", delimiter=",", names=True)
    assert list(series["retried_steps_"]) == [0, 0, 1, 1]


def test_a_restarted_krylov_fast_step_continues_from_the_same_starts(tmp_path):
    """The linearised step's Krylov solve starts from its update extrapolated from the last two
    steps (fluid/krylov_guess.py); the checkpoint carries those updates, so the restarted run
    starts each solve where the uninterrupted run did. One rank, fixed Δt: the two agree to
    1e-11 of max |u| (the Δt of the run's last step differs in its last bits between them, so
    not to the bit); a restart without the updates differs at the Krylov tolerance (4e-6 of
    max |u| on this case)."""
    from fcm_fsi.fluid import solvers
    case = yaml.safe_load((Path(__file__).parents[2] / "cases" / "dam_break.yaml").read_text())
    case["run"] = {"t_end": 0.05, "dt": 1.0e-3, "checkpoint_every": 10, "output_every": 1000}   # fixed Δt
    case["mesh"]["cells"] = [48, 20]
    case["fluid"]["petsc"] = dict(solvers.ITERATIVE_2D)
    case["output"] = {"xdmf": False}
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(case))
    full = run_cli([str(path), "--output", str(tmp_path / "full")], 1)
    assert full.returncode == 0, full.stderr[-2000:]
    run_half_and_resume(path, tmp_path / "half", 0.03)
    with h5py.File(tmp_path / "full" / "checkpoint.h5") as fa, h5py.File(tmp_path / "half" / "checkpoint.h5") as fb:
        assert "dU_last_u" in fa["fields"] and "dU_before_p" in fa["fields"]
        for name in ("U_u", "U_p"):
            a, b = fa[f"fields/{name}/values"][...], fb[f"fields/{name}/values"][...]
            assert np.abs(a - b).max() <= 1e-9 * np.abs(a).max(), name
