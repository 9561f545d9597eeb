"""How close a bonded structure is to breaking, read from a checkpoint.

Every bond point keeps the largest opening λ = δ/δ_f it has reached (``lam_max``, in the
checkpoint's DEM state). Eq 28 turns it into the largest traction the point has carried,
σ/σ_c = 27/4·λ(1 − λ)², whose peak 1 is at λ = 1/3; the point breaks at λ = 1. The report
lists the most loaded points with their two blocks and where they sit in the structure as
built (the blocks' initial poses), and summarises the rest: ``python -m fcm_fsi bond-report``
(fcm_fsi/tools/bond_report.py).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.loader import ConfigError
from .cohesive import shape_g


@dataclass(frozen=True)
class BondPointLoad:
    point: int
    bond: int
    block_a: int
    block_b: int
    position: np.ndarray     # (3,) [m] in the structure as built
    lam_max: float           # largest δ/δ_f reached [-]
    traction_ratio: float    # largest traction carried / σ_c [-] (eq 28 at lam_max; 0 once broken)
    broken: bool


def read_bond_state(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(lam_max, broken) per bond point from a checkpoint (coupled or DEM): the datasets whose
    names end in ``bond_lam_max`` and ``bond_broken``."""
    import h5py
    found: dict[str, np.ndarray] = {}

    def visit(name, obj):
        for key in ("bond_lam_max", "bond_broken"):
            if isinstance(obj, h5py.Dataset) and name.endswith(key):
                found[key] = obj[()]
    try:
        with h5py.File(path, "r") as f:
            f.visititems(visit)
    except OSError as err:
        raise ConfigError(f"{path}: not a readable HDF5 checkpoint ({err})") from None
    if "bond_lam_max" not in found:
        raise ConfigError(f"{path}: holds no bond state (a case without bonded blocks?)")
    lam = np.asarray(found["bond_lam_max"], float)
    broken = np.asarray(found.get("bond_broken", np.zeros(lam.shape, bool)), bool)
    return lam, broken


def traction_ratio(lam_max):
    """Largest traction a bond point has carried / σ_c: eq 28 at its largest opening λ_max,
    capped at the peak 1 once past λ = 1/3."""
    return shape_g(np.minimum(lam_max, 1.0 / 3.0))


def bonded_structure(case_path: Path, overrides: list[str], with_ledger: bool = True):
    """(DEM system, its cohesive bonds) of the case at ``case_path``; ConfigError when the case
    has no DEM or no bonded blocks."""
    from ..config import load_case
    return bonded_structure_of(load_case(case_path, overrides), with_ledger)


def bonded_structure_of(case, with_ledger: bool = True):
    """:func:`bonded_structure` of a loaded case."""
    from .model import build_system
    if case.dem is None:
        raise ConfigError(f"{case.name}: has no dem section")
    system = build_system(case.dem, with_ledger=with_ledger)
    bonds = next((it for it in system.interactions if hasattr(it, "broken_bonds")), None)
    if bonds is None:
        raise ConfigError(f"{case.name}: no bonded blocks in this case")
    return system, bonds


def member_peak_tractions(bonds, lam_max: np.ndarray, broken: np.ndarray,
                          members: list[str]) -> dict[str, float]:
    """Per member (``members[k]`` is block k's member): the largest traction / σ_c carried so
    far by a bond point joining one of its blocks — 1 once a point reached the peak σ_c
    (λ ≥ 1/3, broken or not), NaN for a member without bond points. A point joining two
    members counts for both; blocks beyond the list are left out. A point breaks only at
    λ = 1, past the peak, so 1 means "reached its strength", not "broke"."""
    if lam_max.shape != (bonds.n_points,):
        raise ConfigError(f"the checkpoint has {lam_max.size} bond points, the case builds "
                          f"{bonds.n_points}: not this case's checkpoint")
    names = sorted(set(members))
    code = np.array([names.index(m) for m in members] + [-1])       # [-1]: beyond the list
    ratio = np.where(broken, 1.0, traction_ratio(lam_max))
    peak = np.full(len(names), -np.inf)
    for side in (bonds.pt_a, bonds.pt_b):
        c = code[np.minimum(side, len(members))]
        np.maximum.at(peak, c[c >= 0], ratio[c >= 0])
    return {n: (float(v) if np.isfinite(v) else float("nan")) for n, v in zip(names, peak)}


def member_peak_traction(bonds, lam_max: np.ndarray, broken: np.ndarray, members: list[str],
                         prefix: str) -> float:
    """:func:`member_peak_tractions` over the members whose names start with ``prefix`` (e.g.
    ``wall xmax``: the back wall on every storey); NaN when no such member has bond points."""
    peaks = [v for n, v in member_peak_tractions(bonds, lam_max, broken, members).items()
             if n.startswith(prefix) and np.isfinite(v)]
    return max(peaks) if peaks else float("nan")


def bond_point_loads(bonds, block_pos: np.ndarray, lam_max: np.ndarray,
                     broken: np.ndarray) -> list[BondPointLoad]:
    """Every bond point of ``bonds`` (a :class:`~fcm_fsi.dem.cohesive.CohesiveBonds`) with its
    load, most loaded first; ``block_pos`` = the blocks' centres as built (the points'
    offsets ``pt_ra`` are in that frame)."""
    if lam_max.shape != (bonds.n_points,):
        raise ConfigError(f"the checkpoint has {lam_max.size} bond points, the case builds "
                          f"{bonds.n_points}: not this case's checkpoint")
    where = block_pos[bonds.pt_a] + bonds.pt_ra
    ratio = np.where(broken, 0.0, traction_ratio(lam_max))
    order = np.lexsort((-lam_max, -ratio))
    return [BondPointLoad(int(i), int(bonds.pt_bond[i]), int(bonds.pt_a[i]), int(bonds.pt_b[i]),
                          where[i], float(lam_max[i]), float(ratio[i]), bool(broken[i])) for i in order]


def summary(loads: list[BondPointLoad]) -> dict[str, float]:
    lam = np.array([p.lam_max for p in loads])
    return {"points": float(lam.size), "broken": float(sum(p.broken for p in loads)),
            "largest_traction_ratio": max((p.traction_ratio for p in loads), default=0.0),
            "past_peak": float(np.count_nonzero(lam > 1.0 / 3.0)),
            "share_above_0.1_sigma_c": float(np.mean([p.traction_ratio > 0.1 for p in loads])) if loads else 0.0}


if __name__ == "__main__":     # the former name of `python -m fcm_fsi bond-report` (fcm_fsi/tools/bond_report.py)
    from ..cli import main
    sys.exit(main(["bond-report", *sys.argv[1:]]))
