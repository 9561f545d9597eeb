"""Polynomial cohesive bonds between the faces of adjacent rigid blocks (paper §3(3), eq 28).

Normal law (Needleman 1987), with x = δ/δ_f::

    σ(δ) = 27/4 · σ_c · x · (1 − x)²      for 0 ≤ δ ≤ δ_f,    0 beyond   (eq 28)

peak σ_c at δ = δ_f/3, fracture energy ∫σ dδ = 9/16 · σ_c · δ_f, initial stiffness
k0 = 27/4 · σ_c/δ_f [Pa/m].

Mixed mode (Tvergaard 1990): the law acts on the effective opening

    λ = √((⟨δn⟩/δ_f)² + (δt/δ_tc)²)

through the potential Φ(δn, δt) = σ_c δ_f ψ(λ), ψ(λ) = ∫₀^λ g, g(λ) = 27/4 λ(1 − λ)².
Tractions are its gradient: Tn = σ_c (g/λ) δn/δ_f, Tt = σ_c (g/λ) δt δ_f/δ_tc² — pure
shear has peak σ_c δ_f/δ_tc and the same fracture energy 9/16 σ_c δ_f.
Compression (δn < 0) is a linear penalty Tn = k_pen δn, k_pen = penalty_factor · k0, which
joins the tensile branch with the same slope at δn = 0 when penalty_factor = 1.

Modes: ``reversible`` (the paper: unloading follows eq 28 back) and ``damage`` (unloading
along the secant to the origin from the largest λ reached, λ_max — irreversible). A point
whose λ reaches 1 is broken for good; its faces then meet only through sphere contact.

Each bond (one shared face) is integrated with n×n Gauss–Legendre points; the openings at
each point follow from the relative rigid motion of the two blocks, so a bond carries
tension, shear, bending and torsion. Kernels take arrays only; :func:`traction_reference`
is the plain-NumPy reference of the point law.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..geometry import quat_to_matrix_np, rotate
from . import L_BOND, L_BOND_LOSS

MODES = {"reversible": 0, "damage": 1}

# ---------------------------------------------------------------------------------------
# The law: NumPy reference
# ---------------------------------------------------------------------------------------


def shape_g(lam: np.ndarray) -> np.ndarray:
    """σ/σ_c of eq 28 as a function of x = δ/δ_f (zero for x ≤ 0 and x ≥ 1)."""
    x = np.asarray(lam, dtype=float)
    inside = (x > 0) & (x < 1)
    return np.where(inside, 6.75 * x * (1.0 - x) ** 2, 0.0)


def shape_psi(lam: np.ndarray) -> np.ndarray:
    """Φ/(σ_c δ_f) = ∫₀^x g: the stored energy per area, normalised; 9/16 for x ≥ 1."""
    x = np.clip(np.asarray(lam, dtype=float), 0.0, 1.0)
    return 6.75 * (x ** 2 / 2 - 2 * x ** 3 / 3 + x ** 4 / 4)


def traction_reference(dn, dt, lam_max, broken, *, sigma_c: float, delta_f: float,
                       delta_tc: float, k_pen: float, damage: bool):
    """Point law in plain NumPy (reference for the Numba kernel).

    dn: normal opening [m] (negative = interpenetration); dt: tangential opening magnitude
    [m] (≥ 0); lam_max: largest λ reached so far (both modes track it; only ``damage``
    unloads along its secant); broken: point already broken.
    Returns (Tn [Pa], Tt [Pa], stored [J/m²], dissipated [J/m²], lam_max_new, broken_new).
    """
    dn, dt = np.asarray(dn, float), np.asarray(dt, float)
    lam = np.sqrt((np.maximum(dn, 0.0) / delta_f) ** 2 + (dt / delta_tc) ** 2)
    was_broken = np.asarray(broken, bool)
    lmax = np.where(was_broken, lam_max, np.maximum(lam_max, lam))
    brk = was_broken | (lmax >= 1.0)
    loading = (lam >= lmax) | (not damage)
    g_over_l_load = np.where(lam > 0, shape_g(lam) / np.where(lam > 0, lam, 1.0), 6.75)
    g_over_l_unl = np.where(lmax > 0, shape_g(lmax) / np.where(lmax > 0, lmax, 1.0), 6.75)
    s = np.where(loading, g_over_l_load, g_over_l_unl)
    if damage:  # secant energy; the rest of ψ(λ_max) is dissipated
        stored = 0.5 * s * lam ** 2 * sigma_c * delta_f
    else:
        stored = shape_psi(lam) * sigma_c * delta_f
    tn = sigma_c * s * np.maximum(dn, 0.0) / delta_f
    tt = sigma_c * s * dt * delta_f / delta_tc ** 2
    comp = np.minimum(dn, 0.0)
    tn = tn + k_pen * comp
    stored = stored + 0.5 * k_pen * comp ** 2
    if damage:
        diss = (shape_psi(lmax) - 0.5 * shape_g(lmax) * lmax) * sigma_c * delta_f
    else:
        diss = np.zeros_like(lam)
    full = 0.5625 * sigma_c * delta_f
    tn, tt = np.where(brk, 0.0, tn), np.where(brk, 0.0, tt)
    stored = np.where(brk, 0.0, stored)
    diss = np.where(brk, full, diss)
    return tn, tt, stored, diss, lmax, brk


# ---------------------------------------------------------------------------------------
# The law: Numba kernels
# ---------------------------------------------------------------------------------------


@numba.njit(cache=True)
def _g(x):
    if x <= 0.0 or x >= 1.0:
        return 0.0
    return 6.75 * x * (1.0 - x) * (1.0 - x)


@numba.njit(cache=True)
def _psi(x):
    if x >= 1.0:
        return 0.5625
    if x <= 0.0:
        return 0.0
    return 6.75 * (0.5 * x * x - 2.0 * x * x * x / 3.0 + 0.25 * x * x * x * x)


@numba.njit(cache=True)
def point_law(dn, dt, lam_max, sigma_c, delta_f, delta_tc, k_pen, damage):
    """Scalar point law (see module docstring). Returns (Tn, Tt, stored, dissipated,
    lam_max_new, broken) with Tn, Tt [Pa] and energies [J/m²]."""
    dnp = dn if dn > 0.0 else 0.0
    lam = np.sqrt((dnp / delta_f) ** 2 + (dt / delta_tc) ** 2)
    lmax = lam_max if lam_max > lam else lam
    if lmax >= 1.0:
        return 0.0, 0.0, 0.0, 0.5625 * sigma_c * delta_f, lmax, True
    diss = 0.0
    if not damage:  # reversible: the curve both ways, all work stored
        s = _g(lam) / lam if lam > 0.0 else 6.75
        stored = _psi(lam) * sigma_c * delta_f
    else:  # damage: secant stiffness of λ_max; stored = secant energy, the rest is lost
        if lam >= lmax:  # loading on the curve (λ_max = λ)
            s = _g(lam) / lam if lam > 0.0 else 6.75
        else:
            s = _g(lmax) / lmax
        stored = 0.5 * s * lam * lam * sigma_c * delta_f
        diss = (_psi(lmax) - 0.5 * _g(lmax) * lmax) * sigma_c * delta_f
    tn = sigma_c * s * dnp / delta_f
    tt = sigma_c * s * dt * delta_f / (delta_tc * delta_tc)
    if dn < 0.0:
        tn += k_pen * dn
        stored += 0.5 * k_pen * dn * dn
    return tn, tt, stored, diss, lmax, False


@numba.njit(cache=True)
def point_law_array(dn, dt, lam_max, broken, sigma_c, delta_f, delta_tc, k_pen, damage):
    """:func:`point_law` over arrays (for tests against :func:`traction_reference`)."""
    n = dn.shape[0]
    tn = np.zeros(n)
    tt = np.zeros(n)
    st = np.zeros(n)
    di = np.zeros(n)
    lm = lam_max.copy()
    br = broken.copy()
    for i in range(n):
        if br[i]:
            di[i] = 0.5625 * sigma_c * delta_f
            continue
        tn[i], tt[i], st[i], di[i], lm[i], br[i] = point_law(
            dn[i], dt[i], lam_max[i], sigma_c, delta_f, delta_tc, k_pen, damage)
    return tn, tt, st, di, lm, br


@numba.njit(cache=True)
def bond_forces(pos, quat, pt_a, pt_b, pt_ra, pt_rb, pt_na, pt_area, sigma_c, delta_f,
                delta_tc, k_pen, damage, lam_max, broken, force, torque):
    """Add the forces and torques of all intact bond points to ``force``/``torque``.

    Point p joins block a at body-frame offset pt_ra[p] and block b at pt_rb[p] (the two
    material points coincide in the bonded reference state); pt_na[p] is the face normal
    from a towards b in a's body frame; pt_area[p] its share of the face area [m²].
    Opening d = x_b − x_a; δn = d·n, δt = |d − δn n|. Block a receives +A T at x_a, block b
    −A T at x_b, and block a the torque of its normal's dependence on its rotation.
    ``lam_max`` and ``broken`` are updated in place.
    Returns (stored energy [J], fracture dissipation so far [J]).
    """
    stored = 0.0
    dissipated = 0.0
    full = 0.5625 * sigma_c * delta_f
    for p in range(pt_a.shape[0]):
        if broken[p]:
            dissipated += full * pt_area[p]
            continue
        a = pt_a[p]
        b = pt_b[p]
        qa0, qa1, qa2, qa3 = quat[a, 0], quat[a, 1], quat[a, 2], quat[a, 3]
        qb0, qb1, qb2, qb3 = quat[b, 0], quat[b, 1], quat[b, 2], quat[b, 3]
        ax, ay, az = rotate(qa0, qa1, qa2, qa3, pt_ra[p, 0], pt_ra[p, 1], pt_ra[p, 2])
        bx, by, bz = rotate(qb0, qb1, qb2, qb3, pt_rb[p, 0], pt_rb[p, 1], pt_rb[p, 2])
        nx, ny, nz = rotate(qa0, qa1, qa2, qa3, pt_na[p, 0], pt_na[p, 1], pt_na[p, 2])
        dx = pos[b, 0] + bx - pos[a, 0] - ax
        dy = pos[b, 1] + by - pos[a, 1] - ay
        dz = pos[b, 2] + bz - pos[a, 2] - az
        dn = dx * nx + dy * ny + dz * nz
        tx, ty, tz = dx - dn * nx, dy - dn * ny, dz - dn * nz
        dt = np.sqrt(tx * tx + ty * ty + tz * tz)
        tn, tt, st, di, lm, br = point_law(dn, dt, lam_max[p], sigma_c, delta_f, delta_tc,
                                           k_pen, damage)
        lam_max[p] = lm
        broken[p] = br
        area = pt_area[p]
        stored += st * area
        dissipated += di * area
        if br:
            continue
        fx, fy, fz = tn * area * nx, tn * area * ny, tn * area * nz
        # torque from the normal turning with block a: Φ depends on n through δn and δt,
        # so a rotation of a costs energy; −n × ∂Φ/∂n = −A (Tn − Tt δn/δt) n × d
        c = 0.0
        if dt > 0.0:
            s = tt * area / dt
            fx += s * tx
            fy += s * ty
            fz += s * tz
            c = area * (tn - tt * dn / dt)
        # forces act at the material points x_a, x_b; with the n-torque above the bond is
        # energy-consistent (F = −∂Φ/∂x) and moment-free (angular momentum conserved)
        force[a, 0] += fx
        force[a, 1] += fy
        force[a, 2] += fz
        force[b, 0] -= fx
        force[b, 1] -= fy
        force[b, 2] -= fz
        torque[a, 0] += ay * fz - az * fy - c * (ny * dz - nz * dy)
        torque[a, 1] += az * fx - ax * fz - c * (nz * dx - nx * dz)
        torque[a, 2] += ax * fy - ay * fx - c * (nx * dy - ny * dx)
        torque[b, 0] -= by * fz - bz * fy
        torque[b, 1] -= bz * fx - bx * fz
        torque[b, 2] -= bx * fy - by * fx
    return stored, dissipated


# ---------------------------------------------------------------------------------------
# Faces → integration points, and the interaction object
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CohesiveLaw:
    """Parameters of eq 28 plus mixed mode and compression (SI units)."""

    sigma_c: float          # Pa, peak normal traction
    delta_f: float          # m, normal opening at complete failure
    delta_tc: float         # m, tangential opening that counts as δ_f in λ
    penalty_factor: float   # k_pen / k0 in compression
    mode: str               # 'reversible' | 'damage'

    @property
    def k0(self) -> float:
        """Initial normal stiffness per area 27/4 σ_c/δ_f [Pa/m]."""
        return 6.75 * self.sigma_c / self.delta_f

    @property
    def fracture_energy(self) -> float:
        """9/16 σ_c δ_f [J/m²]."""
        return 0.5625 * self.sigma_c * self.delta_f

    @classmethod
    def from_config(cls, cfg) -> CohesiveLaw:
        """From a :class:`fcm_fsi.config.structure.CohesiveConfig`."""
        return cls(sigma_c=cfg.sigma_c, delta_f=cfg.delta_f,
                   delta_tc=cfg.delta_f if cfg.delta_tc is None else cfg.delta_tc,
                   penalty_factor=cfg.penalty_factor, mode=cfg.mode)


def face_points(centre, axis_u, axis_v, half_u: float, half_v: float, n: int):
    """n×n Gauss–Legendre points of the rectangle centre ± half_u·u ± half_v·v.

    Returns (points (n², 3), areas (n²,)) with areas summing to 4·half_u·half_v. Gauss
    points make the bending and torsional stiffness of a linear opening field exact."""
    xi, w = np.polynomial.legendre.leggauss(n)
    uu, vv = np.meshgrid(xi * half_u, xi * half_v, indexing="ij")
    ww = np.outer(w, w) * half_u * half_v
    pts = (np.asarray(centre, float)[None, :] + uu.reshape(-1, 1) * np.asarray(axis_u, float)
           + vv.reshape(-1, 1) * np.asarray(axis_v, float))
    return pts, ww.reshape(-1)


@dataclass(frozen=True)
class BondFace:
    """A face shared by blocks a and b, in the world frame of the bonded reference state."""

    a: int
    b: int
    centre: tuple[float, float, float]
    normal: tuple[float, float, float]   # unit, from a towards b
    axis_u: tuple[float, float, float]   # unit, in the face
    axis_v: tuple[float, float, float]
    half_u: float
    half_v: float

    @property
    def area(self) -> float:
        return 4.0 * self.half_u * self.half_v


class CohesiveBonds:
    """All cohesive bonds of a model as integration-point arrays; a DEM interaction.

    The DEM calls :meth:`add_forces` each step (the interaction hook); :meth:`compute` is
    the same on bare arrays. :meth:`energies` gives ``cohesive_stored`` [J] and
    ``fracture_dissipation`` [J] (cumulative energy lost to damage and breaking).
    """

    def __init__(self, law: CohesiveLaw, pt_bond, pt_a, pt_b, pt_ra, pt_rb, pt_na, pt_area,
                 bond_area):
        if law.mode not in MODES:
            raise ValueError(f"cohesive mode {law.mode!r}: choose one of {', '.join(MODES)}")
        self.law = law
        self.pt_bond = np.ascontiguousarray(pt_bond, dtype=np.int64)
        self.pt_a = np.ascontiguousarray(pt_a, dtype=np.int64)
        self.pt_b = np.ascontiguousarray(pt_b, dtype=np.int64)
        self.pt_ra = np.ascontiguousarray(pt_ra, dtype=np.float64).reshape(-1, 3)
        self.pt_rb = np.ascontiguousarray(pt_rb, dtype=np.float64).reshape(-1, 3)
        self.pt_na = np.ascontiguousarray(pt_na, dtype=np.float64).reshape(-1, 3)
        self.pt_area = np.ascontiguousarray(pt_area, dtype=np.float64)
        self.bond_area = np.asarray(bond_area, dtype=np.float64)
        self.lam_max = np.zeros(self.n_points)
        self.broken = np.zeros(self.n_points, dtype=np.bool_)
        self.stored = 0.0
        self.dissipated = 0.0

    @property
    def n_points(self) -> int:
        return self.pt_a.shape[0]

    @property
    def n_bonds(self) -> int:
        return self.bond_area.shape[0]

    @classmethod
    def from_faces(cls, law: CohesiveLaw, faces: list[BondFace], pos, quat,
                   points_per_edge: int, points: list | None = None) -> CohesiveBonds:
        """Bonds on ``faces`` of blocks at ``pos``/``quat`` (the bonded reference state).
        ``points``: per face, None for the ``points_per_edge``² Gauss points of its rectangle,
        or its own (points (m, 3) [m], areas (m,) [m²]) (a face the solid covers partly)."""
        R = quat_to_matrix_np(np.asarray(quat, float).reshape(-1, 4))
        pos = np.asarray(pos, float).reshape(-1, 3)
        cols = {k: [] for k in ("bond", "a", "b", "ra", "rb", "na", "area")}
        given = [None] * len(faces) if points is None else points
        for i, (f, own) in enumerate(zip(faces, given)):
            pts, areas = own if own is not None else face_points(f.centre, f.axis_u, f.axis_v, f.half_u,
                                                                 f.half_v, points_per_edge)
            m = len(areas)
            cols["bond"].append(np.full(m, i))
            cols["a"].append(np.full(m, f.a))
            cols["b"].append(np.full(m, f.b))
            cols["ra"].append((pts - pos[f.a]) @ R[f.a])  # Rᵀ(p − x): body frame
            cols["rb"].append((pts - pos[f.b]) @ R[f.b])
            cols["na"].append(np.tile(np.asarray(f.normal, float) @ R[f.a], (m, 1)))
            cols["area"].append(areas)
        if not faces:
            return cls(law, *(np.zeros((0, 3) if k in ("ra", "rb", "na") else 0)
                              for k in cols), bond_area=np.zeros(0))
        return cls(law, *(np.concatenate(cols[k]) for k in cols),
                   bond_area=np.array([f.area if own is None else float(np.sum(own[1]))
                                       for f, own in zip(faces, given)]))

    def compute(self, pos: np.ndarray, quat: np.ndarray, force: np.ndarray,
                torque: np.ndarray) -> None:
        """Add bond forces [N] and torques about the centres of mass [N m] (world frame);
        update damage/breaking and the energies."""
        law = self.law
        self.stored, self.dissipated = bond_forces(
            pos, quat, self.pt_a, self.pt_b, self.pt_ra, self.pt_rb, self.pt_na, self.pt_area,
            law.sigma_c, law.delta_f, law.delta_tc, law.penalty_factor * law.k0,
            law.mode == "damage", self.lam_max, self.broken, force, torque)

    def add_forces(self, state, force: np.ndarray, torque: np.ndarray, ledger: np.ndarray,
                   dt: float) -> None:
        """DEM interaction hook (``fcm_fsi/dem/__init__.py``): forces, torques, and the
        ledger's stored bond energy (L_BOND) and this step's bond dissipation (L_BOND_LOSS)."""
        before = self.dissipated
        self.compute(state.pos, state.quat, force, torque)
        ledger[L_BOND] += self.stored
        ledger[L_BOND_LOSS] += self.dissipated - before

    def energies(self) -> dict[str, float]:
        """Ledger terms after the last force evaluation [J]."""
        return {"cohesive_stored": float(self.stored),
                "fracture_dissipation": float(self.dissipated)}

    def stiffness_bound(self) -> tuple[float, float]:
        """(stiffest bond's axial stiffness A·max(1, penalty_factor, (δ_f/δ_tc)²)·k0 [N/m],
        damping ratio 0) for the DEM's stable time-step check."""
        if self.n_bonds == 0:
            return 0.0, 0.0
        law = self.law
        kfac = max(1.0, law.penalty_factor, (law.delta_f / law.delta_tc) ** 2) * law.k0
        return float(kfac * self.bond_area.max()), 0.0

    def checkpoint_arrays(self) -> dict[str, np.ndarray]:
        return {"bond_lam_max": self.lam_max.copy(), "bond_broken": self.broken.copy(),
                "bond_energy": np.array([self.stored, self.dissipated])}

    def restore(self, arrays) -> None:
        self.lam_max[:] = arrays["bond_lam_max"]
        self.broken[:] = arrays["bond_broken"]
        self.stored, self.dissipated = (float(x) for x in arrays["bond_energy"])

    def broken_bonds(self) -> np.ndarray:
        """Boolean per bond: every integration point of the face is broken."""
        per = np.bincount(self.pt_bond, weights=self.broken.astype(float),
                          minlength=self.n_bonds)
        cnt = np.bincount(self.pt_bond, minlength=self.n_bonds)
        return per >= cnt

    def block_damage(self, nblocks: int) -> np.ndarray:
        """Per block (nblocks,): the fraction of its bonds that are broken, 0 … 1 (0 for a
        block without bonds) — what the block output colours by."""
        first = np.unique(self.pt_bond, return_index=True)[1]       # one point per bond
        a, b = self.pt_a[first], self.pt_b[first]
        broken = self.broken_bonds()[self.pt_bond[first]].astype(float)
        total = np.bincount(a, minlength=nblocks) + np.bincount(b, minlength=nblocks)
        lost = (np.bincount(a, weights=broken, minlength=nblocks)
                + np.bincount(b, weights=broken, minlength=nblocks))
        return np.where(total > 0, lost / np.maximum(total, 1), 0.0)
