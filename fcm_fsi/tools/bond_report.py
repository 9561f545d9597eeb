"""How close a bonded structure came to breaking, read from a checkpoint of its run.

Lists the bond points that carried the largest traction so far (σ/σ_c from their largest
opening λ_max by eq 28, 1 at λ = 1/3; a point breaks at λ = 1) with their two blocks and
where they sit in the structure as built, and summarises the rest::

    python -m fcm_fsi bond-report cases/tsunami_building.yaml OUTPUT/checkpoint.h5 --top 10
    python -m fcm_fsi bond-report cases/tsunami_building.yaml OUTPUT/checkpoint.h5 --members

``--members`` adds the largest traction per building member (the last row of the run's
``member_loads.csv``). The functions are in fcm_fsi/dem/bond_report.py.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..config import ConfigError, load_case
from ..dem.bond_report import bond_point_loads, bonded_structure_of, member_peak_tractions, read_bond_state, summary
from ..dem.failure_sequence import block_members


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("case", type=Path, help="case file (YAML) of the run")
    ap.add_argument("checkpoint", type=Path, help="checkpoint.h5 of the run (coupled or DEM)")
    ap.add_argument("--top", type=int, default=10, help="points to list (default 10)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="the same overrides as the run (only the dem section matters)")
    ap.add_argument("--members", action="store_true",
                    help="per building member (dem.structure): the largest traction carried, as member_loads.csv")


def run(args: argparse.Namespace) -> int:
    try:
        case = load_case(args.case, args.set)
        system, bonds = bonded_structure_of(case)
        lam, broken = read_bond_state(args.checkpoint)
        loads = bond_point_loads(bonds, system.state.pos.copy(), lam, broken)
        if args.members:
            peaks = member_peak_tractions(bonds, lam, broken, block_members(case))
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    s = summary(loads)
    print(f"{int(s['points'])} bond points, {int(s['broken'])} broken, {int(s['past_peak'])} past the peak "
          f"(λ > 1/3); largest traction carried {s['largest_traction_ratio']:.2f} σ_c; "
          f"{100 * s['share_above_0.1_sigma_c']:.1f} % of the points above 0.1 σ_c")
    print("point  bond  blocks      x [m]    y [m]    z [m]   lam_max  traction/σ_c")
    for p in loads[:args.top]:
        state = "broken" if p.broken else f"{p.traction_ratio:.3f}"
        print(f"{p.point:5d} {p.bond:5d} {p.block_a:4d}-{p.block_b:<4d} {p.position[0]:8.2f} {p.position[1]:8.2f} "
              f"{p.position[2]:8.2f}   {p.lam_max:.4f}   {state}")
    if args.members:
        print("member            largest traction/σ_c")
        for name, v in sorted(peaks.items(), key=lambda kv: -np.nan_to_num(kv[1], nan=-1.0)):
            print(f"{name:16s}  {v:.3f}")
    return 0
