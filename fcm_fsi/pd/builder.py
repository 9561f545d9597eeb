"""A :class:`~.system.PDSystem` from the case's ``pd`` section: points (lattice or tetrahedron
centroids), bonds (notches removed), the constitutive law's constants per point and bond,
loads, initial velocity, and the time-step check."""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.loader import ConfigError
from ..config.pd import BOND_BASED_POISSON, PDConfig
from .lattice import in_box, lattice_points
from .loads import PressureLoad, wall_force_per_pascal, wall_layer
from .material import (
    bulk_and_shear,
    critical_stretch,
    family_radius,
    influence,
    micromodulus,
    state_bond_stiffness,
    state_critical_stretch,
    verlet_bound,
    volume_correction,
    weibull_fracture_energy,
    weighted_volume,
)
from .neighbours import bond_lists, compress, hole_keep, notch_array, notch_keep, transpose
from .particles import local_spacing, tet_particles
from .system import BondBased, Bonds, Loads, PDSystem, StateBased


@dataclass
class Points:
    """The body's material points: positions ``x`` (N, 3) [m], volumes ``vol`` [m³], local spacing
    ``spacing`` [m] (Δx, or a particle's :func:`~.particles.local_spacing`), horizon ``horizon`` δ = factor × spacing [m],
    the bounding box ``lower``, ``upper`` [m] and whether bonds carry the lattice's partial-volume
    correction (``partial_volume``; particles: β = 1 inside δ)."""

    x: np.ndarray
    vol: np.ndarray
    spacing: np.ndarray
    horizon: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    partial_volume: bool


def point_volumes(cfg: PDConfig, n: int) -> np.ndarray:
    """Δx³, or Δx² × thickness in 2D [m³]."""
    dx = cfg.lattice.spacing
    return np.full(n, dx ** 3 if cfg.dim == 3 else dx * dx * cfg.thickness)


def build_points(cfg: PDConfig, case_dir: Path | None = None) -> Points:
    """The lattice points, or the centroids of the tetrahedra of ``pd.particles`` (a .msh file
    relative to ``case_dir``, or a box gmsh meshes), with a horizon per point (eq 2)."""
    if cfg.lattice is not None:
        lat = cfg.lattice
        x = body_points(cfg)
        spacing = np.full(len(x), lat.spacing)
        lower, upper = np.asarray(lat.lower, float), np.asarray(lat.upper, float)
        return Points(x, point_volumes(cfg, len(x)), spacing, cfg.horizon_factor * spacing, lower, upper, True)
    x, vol, (lower, upper) = tet_particles(cfg.particles, case_dir)
    spacing = local_spacing(x, vol, cfg.horizon_factor)
    return Points(x, vol, spacing, cfg.horizon_factor * spacing, lower, upper, False)


def build_bonds(cfg: PDConfig, pts: Points) -> Bonds:
    """The owned bonds of every point without those crossing a notch. On a lattice the family is
    |ξ| ≤ δ_p + Δx/2, weighted by the volume correction β; on particles |ξ| ≤ δ_p with β = 1.
    s0 per bond from G0 (Weibull per bond when a shape is given) and the owner's horizon (eq 10;
    the state-based s0 from K and G)."""
    x, horizon, spacing = pts.x, pts.horizon, pts.spacing
    offsets, nbr = bond_lists(x, family_radius(horizon, spacing) if pts.partial_volume else horizon)
    if cfg.notches:
        keep = notch_keep(x, offsets, nbr, notch_array([n.points for n in cfg.notches], cfg.dim))
        offsets, nbr = compress(offsets, nbr, keep)
    for hole in cfg.boreholes:
        offsets, nbr = compress(offsets, nbr, hole_keep(x, offsets, nbr, hole.centre, hole.radius))
    owner = np.repeat(np.arange(len(x), dtype=np.int64), np.diff(offsets))
    length = np.linalg.norm(x[nbr] - x[owner], axis=1)
    if pts.partial_volume:
        beta = volume_correction(length, horizon[owner], spacing[owner])
    else:
        beta = np.ones(len(nbr))
    mat = cfg.material
    if mat.fracture_energy is None:
        s0 = np.full(len(nbr), np.inf)
    else:
        g0 = weibull_fracture_energy(mat.fracture_energy, mat.weibull_shape, len(nbr), mat.weibull_seed)
        if cfg.model == "state_based":
            bulk, shear = bulk_and_shear(mat.youngs_modulus, mat.poisson_ratio)
            s0 = state_critical_stretch(bulk, shear, g0, horizon[owner])
        else:
            s0 = critical_stretch(cfg.formulation, mat.youngs_modulus, g0, horizon[owner])
    dual_offsets, dual_bond = transpose(offsets, nbr)
    return Bonds(offsets, nbr, owner, dual_offsets, dual_bond, length, beta, s0, np.ones(len(nbr), np.uint8))


def build_law(cfg: PDConfig, pts: Points, bonds: Bonds) -> tuple[BondBased | StateBased, np.ndarray]:
    """The constitutive law of ``pd.model`` and the stiffness k of every owned bond for the
    stable-step bound [N/m⁶ per m]."""
    mat, n = cfg.material, len(pts.x)
    if cfg.model == "bond_based":
        nu = BOND_BASED_POISSON[cfg.formulation]
        modulus = micromodulus(cfg.formulation, mat.youngs_modulus, nu, pts.horizon, cfg.thickness)
        return BondBased(modulus), modulus[bonds.owner] * bonds.beta / bonds.length
    k, g = bulk_and_shear(mat.youngs_modulus, mat.poisson_ratio)
    omega = influence(bonds.length, pts.horizon[bonds.owner])
    mvol = weighted_volume(bonds.owner, bonds.nbr, bonds.length, bonds.beta, omega, pts.vol, n)
    bulk, shear = np.full(n, k), np.full(n, g)
    o = bonds.owner
    return StateBased(omega, mvol, bulk, shear), bonds.beta * state_bond_stiffness(bulk[o], shear[o], omega, mvol[o])


def body_points(cfg: PDConfig) -> np.ndarray:
    """The lattice of ``cfg`` without the points inside its boreholes (|x − c| < R)."""
    x = lattice_points(cfg.lattice.lower, cfg.lattice.upper, cfg.lattice.spacing)
    for i, hole in enumerate(cfg.boreholes):
        inside = np.hypot(x[:, 0] - hole.centre[0], x[:, 1] - hole.centre[1]) < hole.radius
        if not inside.any():
            raise ConfigError(f"key 'pd.boreholes[{i}].radius' = {hole.radius:g} m: the hole holds no lattice point "
                              f"(spacing {cfg.lattice.spacing:g} m); allowed: a hole that removes at least one point")
        x = x[~inside]
    return x


def borehole_loads(cfg: PDConfig, x: np.ndarray, vol: np.ndarray) -> tuple[PressureLoad, ...]:
    """The blast pressure of every borehole on its wall layer (``loads.py``)."""
    out = []
    for i, hole in enumerate(cfg.boreholes):
        pts = wall_layer(x, hole.centre, hole.radius, cfg.lattice.spacing)
        if len(pts) == 0:
            raise ConfigError(f"key 'pd.boreholes[{i}]': no lattice point lies within one spacing of the wall")
        force = wall_force_per_pascal(x, vol, pts, hole.centre, hole.radius, cfg.thickness)
        out.append(PressureLoad(pts, force, hole.peak_pressure, hole.rise_time, hole.beta_over_alpha))
    return tuple(out)


def build_loads(cfg: PDConfig, x: np.ndarray, vol: np.ndarray, spacing: np.ndarray | None = None) -> Loads:
    n, dim = len(x), cfg.dim
    fixed, fixed_velocity, body = np.zeros((n, 3), bool), np.zeros((n, 3)), np.zeros((n, 3))
    for i, bc in enumerate(cfg.velocities):
        sel = in_box(x, bc.lower, bc.upper)
        if not sel.any():
            raise ConfigError(f"key 'pd.velocities[{i}]': the region holds no lattice point")
        for a, value in enumerate(bc.velocity):
            if value is not None:
                fixed[sel, a] = True
                fixed_velocity[sel, a] = value
    for i, tr in enumerate(cfg.tractions):
        sel = in_box(x, tr.lower, tr.upper)
        if not sel.any():
            raise ConfigError(f"key 'pd.tractions[{i}]': the region holds no lattice point")
        if tr.layer_thickness is not None:
            h = tr.layer_thickness
        else:
            h = cfg.lattice.spacing if cfg.lattice is not None else float(spacing[sel].mean())
        body[sel, :dim] += np.asarray(tr.traction, float) / h
    return Loads(fixed, fixed_velocity, body, borehole_loads(cfg, x, vol))


def initial_velocity(cfg: PDConfig, x: np.ndarray, body_lower, body_upper) -> np.ndarray:
    v = np.zeros((len(x), 3))
    for i, iv in enumerate(cfg.initial_velocity):
        lower = iv.lower if iv.lower is not None else body_lower
        upper = iv.upper if iv.upper is not None else body_upper
        sel = in_box(x, lower, upper)
        if not sel.any():
            raise ConfigError(f"key 'pd.initial_velocity[{i}]': the region holds no lattice point")
        shape = np.ones(len(x))
        if iv.profile == "half_cosine":
            a = iv.axis
            shape = np.cos(math.pi * (x[:, a] - lower[a]) / (upper[a] - lower[a]))
        v[sel, :cfg.dim] = shape[sel, None] * np.asarray(iv.velocity, float)
    return v


def _body(cfg: PDConfig, case_dir: Path | None) -> tuple[Points, Bonds, BondBased | StateBased, float]:
    """The points, bonds and law of ``cfg`` and the body's stable step Δt_crit [s]."""
    pts = build_points(cfg, case_dir)
    bonds = build_bonds(cfg, pts)
    law, stiffness = build_law(cfg, pts, bonds)
    return pts, bonds, law, verlet_bound(cfg.material.density, pts.vol, bonds.owner, bonds.nbr, stiffness)


def build_system(cfg: PDConfig, case_dir: Path | None = None) -> PDSystem:
    """The body of ``cfg`` (a particle file relative to ``case_dir``); refuses ``pd.dt`` above
    the stable step (ConfigError naming the bound)."""
    pts, bonds, law, dt_crit = _body(cfg, case_dir)
    check_time_step(cfg.dt, dt_crit)
    return PDSystem(pts.x, pts.vol, cfg.material.density, law, bonds, build_loads(cfg, pts.x, pts.vol, pts.spacing),
                    cfg.dt, initial_velocity(cfg, pts.x, pts.lower, pts.upper), horizon=pts.horizon)


def body_stable_time_step(cfg: PDConfig, case_dir: Path | None = None) -> float:
    """Δt_crit of the whole body from its bonds (the bound :func:`build_system` checks)."""
    return _body(cfg, case_dir)[3]


def check_time_step(dt: float, dt_crit: float) -> None:
    """Refuse a step above the stable bound (the message names pd.dt and the bound)."""
    if dt > dt_crit:
        raise ConfigError(f"key 'pd.dt' = {dt:.4g} s exceeds the stable time step Δt_crit = {dt_crit:.4g} s "
                          f"(Silling–Askari bound √(2ρ / Σ_j V_j c_ij/|ξ_ij|)); allowed ≤ {dt_crit:.4g} s, "
                          f"e.g. {0.8 * dt_crit:.3g} s")


def lattice_stable_time_step(cfg: PDConfig) -> float:
    """Δt_crit of an interior point of ``cfg``'s lattice from its stencil alone (no bonds of the
    whole body): the smallest over the body on a regular lattice, where boundary and notch
    points have fewer bonds (bond-based). Used by the pre-run check. A state-based body is
    stiffest at its surface (a point there has a smaller weighted volume m), and a particle body
    has no stencil: their bound is that of all their bonds (:func:`body_stable_time_step`); inf
    for a particle file (its path is relative to the case file; the run checks the bound when it
    builds the body)."""
    if cfg.particles is not None and cfg.particles.file is not None:
        return math.inf
    if cfg.particles is not None or cfg.model == "state_based":
        return body_stable_time_step(cfg)
    dx, delta, dim = cfg.lattice.spacing, cfg.horizon, cfg.dim
    m = int(math.ceil(cfg.horizon_factor)) + 1
    ax = np.arange(-m, m + 1) * dx
    grid = np.stack(np.meshgrid(*([ax] * dim), indexing="ij"), axis=-1).reshape(-1, dim)
    r = np.linalg.norm(grid, axis=1)
    r = r[(r > 0) & (r <= family_radius(delta, dx) * (1 + 1e-12))]
    nu = BOND_BASED_POISSON[cfg.formulation]
    c = float(micromodulus(cfg.formulation, cfg.material.youngs_modulus, nu, delta, cfg.thickness))
    vol = dx ** 3 if dim == 3 else dx * dx * cfg.thickness
    stiff = 2.0 * c * vol * (volume_correction(r, delta, dx) / r).sum()
    return math.sqrt(2.0 * cfg.material.density / stiff)
