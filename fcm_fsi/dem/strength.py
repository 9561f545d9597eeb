"""The paper's identification of σ_c (§4(4)), applied to our joints.

The paper chose σ_c so that a column of its rigid blocks in a three-point bending test
reaches the same peak reaction as a FEM analysis of the concrete column (its ref. 19, an
isotropic damage model of concrete). So σ_c belongs to the paper's joint model, not to
concrete. Another joint model needs its own σ_c to give the same column the same strength.

Our joint (rigid blocks, openings linear over the face, tension by eq 28, compression by
the penalty) fails in bending at M_u = c · σ_c · W, with W = b h²/6. ``section_capacity``
gives c (1.716 for ``penalty_factor`` 1). The DEM ``beam_bending`` verification reaches it
to 1.3 %. A concrete column fails in three-point bending at P = 4 f_fl W / L, where f_fl is
its flexural strength (modulus of rupture). Equal peak reactions with a joint at mid-span
then mean

    σ_c = f_fl / c

The span and the section cancel, except through f_fl's size effect. f_fl comes from the
user (a test or a FEM run, as in the paper) or from fib Model Code 2010:
f_ctm = 0.30 f_ck^(2/3) (eq 5.1-3a, f_ck ≤ 50 MPa), and
f_ctm = α_fl f_ctm,fl with α_fl = 0.06 h^0.7 / (1 + 0.06 h^0.7), h the depth in mm
(eq 5.1-8a). ``python -m fcm_fsi strength`` (fcm_fsi/tools/strength.py) prints the
identification for a case file.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from ..config.loader import ConfigError
from .cohesive import CohesiveLaw, shape_g


def section_capacity(b: float, h: float, law: CohesiveLaw, n: int = 20000) -> float:
    """Ultimate moment [N m] of a b × h joint between rigid blocks under zero axial force.

    Plane sections (openings linear over the face, exact for rigid blocks), tension by
    eq 28, compression by the penalty k_pen = penalty_factor·k0; for each relative rotation
    θ the neutral axis z_n solves N = 0 (N is monotonic in z_n), and M_u = max_θ M(θ).
    Continuum integral (midpoint rule, ``n`` strips), independent of the DEM kernels."""
    from scipy.optimize import brentq
    z = (np.arange(n) + 0.5) * h / n          # height above the tension face
    k_pen = law.penalty_factor * law.k0

    def stress(theta, zn):
        d = theta * (zn - z)                  # opening > 0 below the neutral axis
        return np.where(d > 0, law.sigma_c * shape_g(d / law.delta_f), k_pen * d)

    best = 0.0
    for theta in np.geomspace(1e-4, 50.0, 600) * law.delta_f / h:
        if stress(theta, h).sum() <= 0.0:     # tension side fully broken
            break
        zn = brentq(lambda zn: stress(theta, zn).sum(), 0.0, h, xtol=1e-14 * h)   # noqa: B023 (called here)
        best = max(best, float(np.sum(stress(theta, zn) * (h / 2 - z)) * b * h / n))
    return best


def joint_bending_factor(law: CohesiveLaw) -> float:
    """c = M_u / (σ_c W) of a joint with this law: the joint's flexural strength per σ_c.

    Scale-free: the law enters only through θh/δ_f and penalty_factor, so a unit section is
    enough."""
    return section_capacity(1.0, 1.0, law) / (law.sigma_c / 6.0)


def mc2010_tensile_strength(fck: float) -> float:
    """Mean axial tensile strength f_ctm [Pa] of concrete of characteristic compressive
    strength ``fck`` [Pa], fib Model Code 2010 eq 5.1-3a (grades up to C50)."""
    if not 12e6 <= fck <= 50e6:
        raise ConfigError(f"f_ck = {fck / 1e6:g} MPa: the Model Code formula used here holds for 12–50 MPa")
    return 0.30e6 * (fck / 1e6) ** (2.0 / 3.0)


def mc2010_flexural_strength(fck: float, depth: float) -> float:
    """Mean flexural tensile strength f_ctm,fl [Pa] of a plain concrete beam ``depth`` [m]
    deep, fib Model Code 2010 eq 5.1-8a: f_ctm = α_fl f_ctm,fl, α_fl = 0.06 h^0.7/(1 + 0.06 h^0.7)
    with h in mm."""
    if not depth > 0:
        raise ConfigError(f"depth = {depth} m: must be > 0")
    a = 0.06 * (depth * 1e3) ** 0.7
    return mc2010_tensile_strength(fck) * (1.0 + a) / a


@dataclass(frozen=True)
class Identification:
    bending_factor: float      # c = M_u/(σ_c W) of the case's joint law
    sigma_c_case: float        # [Pa] the case's σ_c
    flexural_target: float     # [Pa] the concrete's flexural strength

    @property
    def flexural_case(self) -> float:
        """c·σ_c [Pa]: the flexural strength the case's joints give a member."""
        return self.bending_factor * self.sigma_c_case

    @property
    def sigma_c_identified(self) -> float:
        """f_fl/c [Pa]: the σ_c that gives our column the concrete's peak reaction."""
        return self.flexural_target / self.bending_factor

    @property
    def strength_ratio(self) -> float:
        """The case's member strength over the concrete's (> 1: the case's joints are stronger)."""
        return self.flexural_case / self.flexural_target


def identify(law: CohesiveLaw, flexural_strength: float) -> Identification:
    """σ_c giving a joint at mid-span the three-point-bending peak of a member of flexural
    strength ``flexural_strength`` [Pa] (the paper's identification, §4(4))."""
    if not flexural_strength > 0:
        raise ConfigError(f"flexural strength {flexural_strength} Pa: must be > 0")
    return Identification(bending_factor=joint_bending_factor(law), sigma_c_case=law.sigma_c,
                          flexural_target=flexural_strength)


def identify_concrete(case, fck: float, depth: float | None = None) -> tuple[Identification, float]:
    """:func:`identify` for the case's bond law against plain concrete of ``fck`` [Pa] (fib
    MC2010 flexural strength of a member ``depth`` [m] deep, default the depth of the case's
    column along x). Returns the identification and the depth used; ConfigError when the case
    has no bonds, or no structure and no depth."""
    law = bond_law(case)
    if depth is None:
        if case.dem.structure is None:
            raise ConfigError("no dem.structure: give the member depth (--depth)")
        depth = case.dem.structure.column[0]
    return identify(law, mc2010_flexural_strength(fck, depth)), depth


def bond_law(case) -> CohesiveLaw:
    """The case's cohesive law; ConfigError when it has none."""
    if case.dem is None or case.dem.cohesive is None:
        raise ConfigError("has no dem.cohesive (nothing to identify)")
    return CohesiveLaw.from_config(case.dem.cohesive)


if __name__ == "__main__":     # the former name of `python -m fcm_fsi strength` (fcm_fsi/tools/strength.py)
    from ..cli import main
    sys.exit(main(["strength", *sys.argv[1:]]))
