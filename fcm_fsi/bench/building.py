"""Benchmark: the paper's building (``builder.PAPER_BUILDING``) collapsing under gravity.

    python -m fcm_fsi bench building [--t-end 1.0] [--dt 1e-5] [--out DIR] [--mode reversible]

The ground-floor columns and walls (all storey-0 vertical members) are removed at t = 0, so
the upper storey, still bonded, falls 3.3 m onto a ground plane and breaks. DEM only:
sphere–sphere and sphere–ground contact with the paper's K = 1.0e7 N/m, e = 0.2, friction
30°, cohesive bonds σ_c = 1.0e7 Pa, δ_f = 0.02 m, Δt = 1.0e-5 s. Reports wall time,
sphere-steps/s and bond-point updates/s (bond kernel alone and whole step), broken bonds,
the ledger balance, and renders the start and end states.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from ..dem.builder import KINDS, Structure, build_building, paper_building
from ..dem.cohesive import CohesiveLaw
from ..io.logging import get_logger, setup_logging

log = get_logger("bench.building")


def box_corners(lo, hi, pos0, pos, quat) -> np.ndarray:
    """(nb, 8, 3) world corners of boxes built at lo/hi, now at pos/quat."""
    from ..geometry import quat_to_matrix_np
    c = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    local = lo[:, None, :] + c[None] * (hi - lo)[:, None, :] - pos0[:, None, :]
    R = quat_to_matrix_np(quat)
    return pos[:, None, :] + np.einsum("bij,bkj->bki", R, local)


def render(ax, corners, colours, title: str) -> None:
    """Draw boxes given by their 8 corners on a 3D axis."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    polys, cols = [], []
    for b in range(corners.shape[0]):
        for q in quads:
            polys.append(corners[b, list(q)])
            cols.append(colours[b])
    ax.add_collection3d(Poly3DCollection(polys, facecolors=cols, edgecolors="k", linewidths=0.2))
    lo, hi = corners.reshape(-1, 3).min(0), corners.reshape(-1, 3).max(0)
    span = (hi - lo).max()
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - span / 2, mid[0] + span / 2)
    ax.set_ylim(mid[1] - span / 2, mid[1] + span / 2)
    ax.set_zlim(max(0.0, mid[2] - span / 2), max(0.0, mid[2] - span / 2) + span)
    ax.set_xlabel("x [m] (flow →)")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.set_title(title, fontsize=9)


KIND_COLOURS = {"column": "#b0413e", "wall": "#d9d4c7", "slab": "#7f8c99", "block": "#cccccc"}


def render_building(s: Structure, path: Path, title: str) -> None:
    """PNG of a built structure, coloured by member kind."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ax.view_init(elev=22, azim=-128)
    corners = box_corners(s.lo, s.hi, s.pos, s.pos, s.quat)
    render(ax, corners, [KIND_COLOURS[KINDS[k]] for k in s.kind], title)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def run(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python -m fcm_fsi bench building", description=__doc__.split("\n")[0])
    p.add_argument("--t-end", type=float, default=1.0, help="simulated time [s]")
    p.add_argument("--dt", type=float, default=1.0e-5, help="DEM time step [s]")
    p.add_argument("--mode", choices=("reversible", "damage"), default=None, help="override the bond mode")
    p.add_argument("--remove", choices=("ground", "none"), default="ground",
                   help="ground: remove the storey-0 columns and walls (default); none: intact")
    p.add_argument("--out", type=Path, default=Path("bench_building"), help="output directory")
    args = p.parse_args(argv)
    setup_logging("INFO", rank=0)
    from ..dem.contact import Materials, SphereContact
    from ..dem.restitution import damping_ratio
    from ..dem.system import DEMSystem
    from ..dem.wall_contact import WallContact

    cfg, coh = paper_building()
    full = build_building(cfg)
    keep = ~((full.storey == 0) & np.isin(full.kind, [KINDS.index("column"), KINDS.index("wall")]))
    if args.remove == "none":
        keep[:] = True
    s = full.subset(keep)
    law = CohesiveLaw.from_config(coh)
    if args.mode is not None:
        law = CohesiveLaw(**{**law.__dict__, "mode": args.mode})
    bonds = s.bonds(law, coh.points_per_edge)
    state = s.to_state()
    mats = Materials([1.0e7], [1.0e7], [damping_ratio(0.2)], [math.tan(math.radians(30.0))])
    contact = SphereContact(mats, skin=0.3 * cfg.sphere_radius, clip_normal=True)
    ground = WallContact(mats, [[0.0, 0.0, 1.0, 0.0]], [0], np.zeros((0, 3, 3)), [], [], state.ns)
    timed = _Timed(bonds)
    system = DEMSystem(state, [contact, ground, timed], args.dt)
    dtc = system.critical_time_step()
    log.info("building: %d of %d blocks, %d spheres, %d bonds, "
             "%d bond points; dt = %.3g s = %.4f Δt_cr", s.nb, full.nb, state.ns, bonds.n_bonds,
             bonds.n_points, args.dt, args.dt / dtc)
    args.out.mkdir(parents=True, exist_ok=True)
    corners0 = box_corners(s.lo, s.hi, s.pos, state.pos, state.quat)
    nsteps = int(round(args.t_end / args.dt))
    system.step()  # compile outside the timing
    t0 = time.perf_counter()
    timed.seconds = 0.0
    for n in range(1, nsteps):
        system.step()
        if n % max(1, nsteps // 10) == 0:
            led = system.ledger.last
            log.info("t = %.3f s: %d bonds broken, lowest block centre z = %.2f m, kinetic %.4g J, "
                     "bond stored %.4g J, bond loss %.4g J, contact spring+dashpot+friction "
                     "%.4g J, balance error %.4g J, wall %.1f s", state.t,
                     int(bonds.broken_bonds().sum()), state.pos[:, 2].min(),
                     led["kinetic_trans"] + led["kinetic_rot"], bonds.stored, led["bond_loss"],
                     led["spring"] - bonds.stored + led["dashpot_loss"] + led["friction_loss"],
                     led["balance_error"], time.perf_counter() - t0)
    wall = time.perf_counter() - t0
    steps = nsteps - 1
    led = system.ledger.last
    res = {"blocks": s.nb, "spheres": state.ns, "bonds": bonds.n_bonds, "bond_points": bonds.n_points,
           "steps": steps, "dt": args.dt, "t_end": state.t, "wall_s": wall,
           "sphere_steps_per_s": state.ns * steps / wall,
           "bond_point_updates_per_s_kernel": bonds.n_points * steps / timed.seconds,
           "bond_point_updates_per_s_overall": bonds.n_points * steps / wall,
           "bond_share_of_step": timed.seconds / wall,
           "broken_bonds": int(bonds.broken_bonds().sum()),
           "broken_points": int(bonds.broken.sum()),
           "fracture_dissipation_J": bonds.dissipated,
           "kinetic_J": led["kinetic_trans"] + led["kinetic_rot"],
           "ledger_balance_rel": led["balance_rel"], "mode": law.mode}
    (args.out / "building.json").write_text(json.dumps(res, indent=2) + "\n")
    log.info("%s", json.dumps(res, indent=2))
    _render_states(args.out / "building_collapse.png", s, corners0,
                   box_corners(s.lo, s.hi, s.pos, state.pos, state.quat), state.t)
    return 0


class _Timed:
    """Wraps an interaction and accumulates the time spent in it."""

    def __init__(self, inner):
        self.inner = inner
        self.seconds = 0.0

    def add_forces(self, state, force, torque, ledger, dt):
        t0 = time.perf_counter()
        self.inner.add_forces(state, force, torque, ledger, dt)
        self.seconds += time.perf_counter() - t0

    def stiffness_bound(self):
        return self.inner.stiffness_bound()


def _render_states(path: Path, s: Structure, c0, c1, t: float) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(12, 5.5))
    colours = [KIND_COLOURS[KINDS[k]] for k in s.kind]
    both = np.concatenate([c0, c1])
    for i, (c, title) in enumerate(((c0, "t = 0"),
                                    (c1, f"t = {t:.2f} s"))):
        ax = fig.add_subplot(1, 2, i + 1, projection="3d")
        ax.view_init(elev=18, azim=-128)
        render(ax, c, colours, title)
        lo, hi = both.reshape(-1, 3).min(0), both.reshape(-1, 3).max(0)
        span = (hi - lo).max()
        mid = 0.5 * (lo + hi)
        ax.set_xlim(mid[0] - span / 2, mid[0] + span / 2)
        ax.set_ylim(mid[1] - span / 2, mid[1] + span / 2)
        ax.set_zlim(0, span)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
