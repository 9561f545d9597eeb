"""The σ_c that makes a case's bonded blocks as strong as a given concrete, identified as the
paper did (§4(4)): a column's three-point-bending peak equal to the concrete's, σ_c = f_fl / c
with c the joint's bending strength per σ_c (fcm_fsi/dem/strength.py, docs/cohesive.md §2)::

    python -m fcm_fsi strength cases/tsunami_building.yaml --fck 30
    python -m fcm_fsi strength cases/tsunami_building.yaml --flexural-strength 3.6

The flexural strength f_fl comes from fib Model Code 2010 (``--fck``) or from a test or FEM
run (``--flexural-strength``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..config import ConfigError, load_case
from ..dem.strength import bond_law, identify, identify_concrete


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("case", type=Path, help="a case with dem.cohesive (and dem.structure for the column depth)")
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--fck", type=float, help="characteristic compressive strength [MPa] (fib MC2010 f_ctm,fl)")
    src.add_argument("--flexural-strength", type=float, help="the member's flexural strength [MPa] (a test or FEM)")
    ap.add_argument("--depth", type=float, help="member depth [m] for MC2010's size effect (default: the column's x size)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="case overrides")


def run(args: argparse.Namespace) -> int:
    try:
        case = load_case(args.case, args.set)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        if args.fck is not None:
            r, depth = identify_concrete(case, args.fck * 1e6, args.depth)
            source = f"fib MC2010, f_ck {args.fck:g} MPa, depth {depth:g} m"
        else:
            r, source = identify(bond_law(case), args.flexural_strength * 1e6), "given"
    except ConfigError as err:
        print(f"error: {args.case}: {err}", file=sys.stderr)
        return 2
    law = case.dem.cohesive
    print(f"joint law: sigma_c {r.sigma_c_case:.4g} Pa, delta_f {law.delta_f:g} m, penalty_factor {law.penalty_factor:g}")
    print(f"joint bending strength M_u = {r.bending_factor:.4f} sigma_c W")
    print(f"flexural strength of a member with the case's joints: {r.flexural_case / 1e6:.3f} MPa")
    print(f"concrete flexural strength ({source}): {r.flexural_target / 1e6:.3f} MPa")
    print(f"identified sigma_c = {r.sigma_c_identified:.4g} Pa  (the case's is {r.strength_ratio:.2f} x stronger)")
    return 0
