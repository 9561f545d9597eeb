"""The failure sequence of a bonded building: which member broke first, which next.

A run with bonded blocks writes ``bond_breaks.csv`` (time, bond, its two blocks for every bond
that breaks). This module names every block of a ``dem.structure`` building by its member —
``wall xmin s0`` is the ground-floor wall on the x-min side (the tsunami's front wall: the
water comes from −x), ``column s1`` a first-floor column, ``slab s0`` the first floor,
``foundation`` — and orders the members by the time of their first broken bond
(``python -m fcm_fsi failure-sequence OUTPUT_DIR``, fcm_fsi/tools/failure_sequence.py).

A bond joining two members counts for both (a wall torn off its column fails both). The
structure's blocks are the last of the case's blocks (before them: ``dem.blocks``, then the
generators), the foundation last of all.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from ..config.loader import ConfigError
from ..config.structure import StructureConfig
from .builder import KINDS, building_boxes
from .model import described_blocks


@dataclass(frozen=True)
class MemberFailure:
    member: str
    first_break: float      # time of the member's first broken bond [s]
    bonds: int              # bonds of the member broken by the end of the record
    last_break: float       # time of its last broken bond [s]


def member_names(cfg: StructureConfig) -> list[str]:
    """The member of every block of ``build_building(cfg)``, in its block order."""
    lo, hi, kind, storey = building_boxes(cfg)
    ox, oy, _ = cfg.origin
    lines = {"xmin": (0, ox), "xmax": (0, ox + sum(cfg.bays_x)),
             "ymin": (1, oy), "ymax": (1, oy + sum(cfg.bays_y))}
    centre = 0.5 * (lo + hi)
    names = []
    for c, k, s in zip(centre, kind, storey):
        name = KINDS[k]
        if name == "wall":     # a wall block is centred on its side's grid line across its thickness
            side = min(lines, key=lambda n: abs(c[lines[n][0]] - lines[n][1]))
            name = f"wall {side}"
        names.append("foundation" if name == "foundation" else f"{name} s{s}")
    return names


def failure_sequence(t: np.ndarray, block_a: np.ndarray, block_b: np.ndarray,
                     names: list[str]) -> list[MemberFailure]:
    """Members in the order of their first broken bond (ties: by name). ``t``, ``block_a``,
    ``block_b`` are the columns of ``bond_breaks.csv``; ``names[k]`` is the member of block k
    (:func:`block_members`); a block beyond the list is named ``block N``."""
    def name(k: int) -> str:
        return names[k] if 0 <= k < len(names) else f"block {k}"

    seen: dict[str, list[float]] = {}
    for ti, a, b in zip(np.asarray(t, float), block_a, block_b):
        for m in {name(int(a)), name(int(b))}:
            seen.setdefault(m, []).append(float(ti))
    out = [MemberFailure(m, min(ts), len(ts), max(ts)) for m, ts in seen.items()]
    return sorted(out, key=lambda f: (f.first_break, f.member))


def block_members(case) -> list[str]:
    """The member of every block of ``case`` (a loaded case with a ``dem.structure``), indexed
    by block number: ``block N`` for the blocks before the structure (``dem.blocks``, then the
    generators), then :func:`member_names` of the structure."""
    if case.dem is None or case.dem.structure is None:
        raise ConfigError(f"case {case.name!r}: no dem.structure (no building to name)")
    first = sum(count for _, _, count in described_blocks(case.dem))
    return [f"block {k}" for k in range(first)] + member_names(case.dem.structure)


def sequence_of_case(case, t: np.ndarray, block_a: np.ndarray, block_b: np.ndarray) -> list[MemberFailure]:
    """:func:`failure_sequence` of the bond breaks (t, block_a, block_b) of a run of ``case``
    (a loaded case with a ``dem.structure``)."""
    return failure_sequence(t, block_a, block_b, block_members(case))


if __name__ == "__main__":     # the former name of `python -m fcm_fsi failure-sequence` (fcm_fsi/tools/failure_sequence.py)
    from ..cli import main
    sys.exit(main(["failure-sequence", *sys.argv[1:]]))
