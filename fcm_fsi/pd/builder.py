"""A :class:`~.system.PDSystem` from the case's ``pd`` section: lattice, bonds (notches removed),
material constants per point and bond, loads, initial velocity, and the time-step check."""
from __future__ import annotations

import math

import numpy as np

from ..config.loader import ConfigError
from ..config.pd import BOND_BASED_POISSON, PDConfig
from .lattice import in_box, lattice_points
from .loads import PressureLoad, wall_force_per_pascal, wall_layer
from .material import (
    critical_stretch,
    family_radius,
    micromodulus,
    stable_time_step,
    volume_correction,
    weibull_fracture_energy,
)
from .neighbours import bond_lists, compress, hole_keep, notch_array, notch_keep, transpose
from .system import Bonds, Loads, PDSystem


def point_volumes(cfg: PDConfig, n: int) -> np.ndarray:
    """Δx³, or Δx² × thickness in 2D [m³]."""
    dx = cfg.lattice.spacing
    return np.full(n, dx ** 3 if cfg.dim == 3 else dx * dx * cfg.thickness)


def build_bonds(cfg: PDConfig, x: np.ndarray, horizon: np.ndarray, spacing: np.ndarray) -> Bonds:
    """The owned bonds of every point (|ξ| ≤ δ_p + Δx_p/2, weighted by the volume correction β),
    without those crossing a notch; s0 per bond from G0 (Weibull per bond when a shape is given)
    and the owner's horizon (eq 10)."""
    offsets, nbr = bond_lists(x, family_radius(horizon, spacing))
    if cfg.notches:
        keep = notch_keep(x, offsets, nbr, notch_array([n.points for n in cfg.notches], cfg.dim))
        offsets, nbr = compress(offsets, nbr, keep)
    for hole in cfg.boreholes:
        offsets, nbr = compress(offsets, nbr, hole_keep(x, offsets, nbr, hole.centre, hole.radius))
    owner = np.repeat(np.arange(len(x), dtype=np.int64), np.diff(offsets))
    length = np.linalg.norm(x[nbr] - x[owner], axis=1)
    beta = volume_correction(length, horizon[owner], spacing[owner])
    mat = cfg.material
    if mat.fracture_energy is None:
        s0 = np.full(len(nbr), np.inf)
    else:
        g0 = weibull_fracture_energy(mat.fracture_energy, mat.weibull_shape, len(nbr), mat.weibull_seed)
        s0 = critical_stretch(cfg.formulation, mat.youngs_modulus, g0, horizon[owner])
    dual_offsets, dual_bond = transpose(offsets, nbr)
    return Bonds(offsets, nbr, owner, dual_offsets, dual_bond, length, beta, s0, np.ones(len(nbr), np.uint8))


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


def build_loads(cfg: PDConfig, x: np.ndarray, vol: np.ndarray | None = None) -> Loads:
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
        h = tr.layer_thickness or cfg.lattice.spacing
        body[sel, :dim] += np.asarray(tr.traction, float) / h
    vol = point_volumes(cfg, n) if vol is None else vol
    return Loads(fixed, fixed_velocity, body, borehole_loads(cfg, x, vol))


def initial_velocity(cfg: PDConfig, x: np.ndarray) -> np.ndarray:
    v = np.zeros((len(x), 3))
    for i, iv in enumerate(cfg.initial_velocity):
        lower = iv.lower if iv.lower is not None else cfg.lattice.lower
        upper = iv.upper if iv.upper is not None else cfg.lattice.upper
        sel = in_box(x, lower, upper)
        if not sel.any():
            raise ConfigError(f"key 'pd.initial_velocity[{i}]': the region holds no lattice point")
        shape = np.ones(len(x))
        if iv.profile == "half_cosine":
            a = iv.axis
            shape = np.cos(math.pi * (x[:, a] - lower[a]) / (upper[a] - lower[a]))
        v[sel, :cfg.dim] = shape[sel, None] * np.asarray(iv.velocity, float)
    return v


def build_system(cfg: PDConfig) -> PDSystem:
    """The body of ``cfg``; refuses ``pd.dt`` above the stable step (ConfigError naming the bound)."""
    x = body_points(cfg)
    n = len(x)
    spacing = np.full(n, cfg.lattice.spacing)
    horizon = cfg.horizon_factor * spacing                     # δ per point (dual horizon, eq 2)
    vol = point_volumes(cfg, n)
    mat = cfg.material
    nu = BOND_BASED_POISSON[cfg.formulation]
    modulus = micromodulus(cfg.formulation, mat.youngs_modulus, nu, horizon, cfg.thickness)
    bonds = build_bonds(cfg, x, horizon, spacing)
    dt_crit = stable_time_step(mat.density, vol, bonds.owner, bonds.nbr, bonds.length, bonds.beta, modulus)
    check_time_step(cfg.dt, dt_crit)
    return PDSystem(x, vol, mat.density, modulus, bonds, build_loads(cfg, x, vol), cfg.dt, initial_velocity(cfg, x))


def check_time_step(dt: float, dt_crit: float) -> None:
    """Refuse a step above the stable bound (the message names pd.dt and the bound)."""
    if dt > dt_crit:
        raise ConfigError(f"key 'pd.dt' = {dt:.4g} s exceeds the stable time step Δt_crit = {dt_crit:.4g} s "
                          f"(Silling–Askari bound √(2ρ / Σ_j V_j c_ij/|ξ_ij|)); allowed ≤ {dt_crit:.4g} s, "
                          f"e.g. {0.8 * dt_crit:.3g} s")


def lattice_stable_time_step(cfg: PDConfig) -> float:
    """Δt_crit of an interior point of ``cfg``'s lattice from its stencil alone (no bonds of the
    whole body): the smallest over the body on a regular lattice, where boundary and notch
    points have fewer bonds. Used by the pre-run check."""
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
