"""How many times a recorded fluid load a bonded structure carries before a bond breaks.

A coupled run writes every block's fluid force and torque each step (``bodies.csv``). This
tool takes that load at one instant, builds the case's DEM alone (bonds, contacts, walls,
gravity), lets it settle under gravity, then applies α × the recorded load with α ramped
linearly from 0 and reports the load factors α at which the first bond point reaches its
strength σ_c (λ = 1/3) and at which it breaks (λ = 1), where, and how the largest traction
grew with α. A ramp slow against the structure's own
periods is a quasi-static pushover: α ≈ 1 means the recorded load is the structure's
strength, α = 2.5 that it would take 2.5 times that load::

    python -m fcm_fsi load-factor cases/tsunami_building.yaml OUTPUT/bodies.csv --time 1.37

The load is held in direction and distribution (each block keeps its own share); only its
size grows. Bonds follow the case's law (reversible: unloading follows eq 28; a point that
passes the peak softens and, under a growing load, opens to λ = 1 within a few of the
structure's periods).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.loader import ConfigError
from ..dem.bond_report import bonded_structure, traction_ratio
from ..io.csv import read_series


@dataclass(frozen=True)
class RecordedLoad:
    time: float              # [s] the row of bodies.csv used
    force: np.ndarray        # (nb, 3) [N] fluid force per block
    torque: np.ndarray       # (nb, 3) [N m] fluid torque per block about its centre of mass


@dataclass(frozen=True)
class PushoverResult:
    first_peak: float | None       # load factor at which the first bond point reached σ_c (λ = 1/3: cracking starts)
    first_break: float | None      # load factor at which the first bond point broke (λ = 1); None: none up to the maximum
    broken_points: np.ndarray      # bond points broken at that moment
    history: np.ndarray            # (n, 3): load factor, largest traction carried so far / σ_c, broken points


def recorded_load(path: Path, time: float, nb: int) -> RecordedLoad:
    """Fluid force and torque on every block at the ``bodies.csv`` row nearest ``time``."""
    try:
        d = read_series(path)
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err})") from None
    need = ("t", "block", "fx", "fy", "fz", "tx", "ty", "tz")
    if any(k not in d for k in need):
        raise ConfigError(f"{path}: not a bodies.csv (needs the columns {', '.join(need)})")
    n = int(d["block"].max()) + 1
    if n != nb:
        raise ConfigError(f"{path}: has {n} blocks, the case builds {nb}: not this case's run")
    whole = d["t"].size // nb * nb          # a run killed mid-write may leave a partial last step
    if whole == 0:
        raise ConfigError(f"{path}: holds no complete step")
    t = d["t"][:whole].reshape(-1, nb)[:, 0]
    if not t[0] - 1e-9 <= time <= t[-1] + 1e-9:
        raise ConfigError(f"--time {time} s is outside the recorded [{t[0]:.6g}, {t[-1]:.6g}] s of {path}")
    i = int(np.argmin(np.abs(t - time)))
    rows = slice(i * nb, (i + 1) * nb)
    return RecordedLoad(float(t[i]), np.column_stack([d[k][rows] for k in ("fx", "fy", "fz")]),
                        np.column_stack([d[k][rows] for k in ("tx", "ty", "tz")]))


def ramp_to_first_break(system, bonds, load: RecordedLoad, *, max_factor: float, ramp_time: float,
                        settle_time: float = 0.2, report_every: float = 0.01,
                        progress=None) -> PushoverResult:
    """Settle ``system`` under gravity for ``settle_time`` [s], forget the bonds' largest
    openings, then ramp α from 0 to ``max_factor`` over ``ramp_time`` [s] (α updated every DEM
    step) until a bond point breaks. ``history`` is sampled every ``report_every`` [s]."""
    st = system.state
    st.ext_force[:] = 0.0
    st.ext_torque[:] = 0.0
    system.run(int(round(settle_time / system.dt)))
    if bonds.broken.any():
        raise ConfigError(f"{int(np.count_nonzero(bonds.broken))} bond points broke under gravity alone")
    bonds.lam_max[:] = 0.0
    n_ramp = max(1, int(round(ramp_time / system.dt)))
    every = max(1, int(round(report_every / system.dt)))
    history = []
    first_peak = None
    for k in range(1, n_ramp + 1):
        alpha = max_factor * k / n_ramp
        st.ext_force[:] = alpha * load.force
        st.ext_torque[:] = alpha * load.torque
        system.step()
        if first_peak is None and bonds.lam_max.max() >= 1.0 / 3.0:
            first_peak = alpha
        broke = bool(bonds.broken.any())
        if k % every == 0 or broke or k == n_ramp:
            row = (alpha, float(traction_ratio(bonds.lam_max.max())), float(np.count_nonzero(bonds.broken)))
            history.append(row)
            if progress is not None:
                progress(row)
        if broke:
            return PushoverResult(first_peak, alpha, np.flatnonzero(bonds.broken), np.array(history))
    return PushoverResult(first_peak, None, np.zeros(0, int), np.array(history))


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("case", type=Path, help="case file (YAML) with bonded blocks")
    ap.add_argument("bodies", type=Path, help="bodies.csv of a run of this case")
    ap.add_argument("--time", type=float, required=True, help="instant of the load [s] (nearest recorded row)")
    ap.add_argument("--max-factor", type=float, default=5.0, help="largest load factor tried (default 5)")
    ap.add_argument("--ramp", type=float, default=3.0,
                    help="simulated time [s] of the ramp 0 → max factor (default 3; slow against the structure's periods)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="case overrides (the dem section matters)")


def run(args: argparse.Namespace) -> int:
    try:
        if not args.max_factor > 0 or not args.ramp > 0:
            raise ConfigError(f"--max-factor ({args.max_factor}) and --ramp ({args.ramp}) must be > 0")
        system, bonds = bonded_structure(args.case, args.set, with_ledger=False)
        load = recorded_load(args.bodies, args.time, system.state.nb)
        pos0 = system.state.pos.copy()
        total = load.force.sum(axis=0)
        print(f"load at t = {load.time:.6g} s: total force ({total[0]:.4g}, {total[1]:.4g}, {total[2]:.4g}) N; "
              f"ramp 0 → {args.max_factor} over {args.ramp} s, DEM dt {system.dt:.3g} s")
        print("  factor  largest traction/σ_c  broken points")
        result = ramp_to_first_break(system, bonds, load, max_factor=args.max_factor, ramp_time=args.ramp,
                                     report_every=args.ramp / 50,
                                     progress=lambda r: print(f"  {r[0]:6.3f}  {r[1]:8.3f}  {int(r[2]):6d}", flush=True))
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if result.first_peak is not None:
        print(f"first bond point at its strength σ_c (λ = 1/3) at {result.first_peak:.3f} × the load")
    if result.first_break is None:
        print(f"no bond point broke up to {args.max_factor} × the load")
        return 0
    print(f"first break at {result.first_break:.3f} × the load recorded at t = {load.time:.6g} s:")
    for p in result.broken_points:
        w = pos0[bonds.pt_a[p]] + bonds.pt_ra[p]
        print(f"  bond point {p} (bond {bonds.pt_bond[p]}, blocks {bonds.pt_a[p]}-{bonds.pt_b[p]}) "
              f"at ({w[0]:.2f}, {w[1]:.2f}, {w[2]:.2f}) m as built")
    return 0

