"""Time-dependent loads of a peridynamic body, independent of the constitutive model: the blast
pressure of a borehole (seed eq 12) applied as a body force on the points along its wall.

A borehole of radius R is a circle with no points inside and no bond across it. Its wall carries
the pressure P(t): the points at R ≤ |x − c| < R + Δx (the wall layer) get the body force
b_i = P(t) n_i 2πR h / V_layer [N/m³], n_i the outward radial unit vector and V_layer the volume of
the layer's points, so that the radial forces add up to Σ |b_i| V_i = P(t) × 2πR × h — the pressure
times the wall's area (h the thickness of the 2D body). It is the traction load of ``pd.tractions``
(t/h on a layer of thickness h ≈ Δx) bent around the hole.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def decay_rates(rise_time: float, beta_over_alpha: float) -> tuple[float, float]:
    """(α, β) [1/s] of eq 12 from the rise time t0 and k = β/α > 1. P is largest where
    dP/dt = 0, −α e^{−αt} + β e^{−βt} = 0, i.e. t0 = ln(β/α)/(β − α) = ln k / (α (k − 1)); so
    α = ln k / ((k − 1) t0) and β = k α."""
    k = float(beta_over_alpha)
    if not k > 1.0:
        raise ValueError(f"β/α = {k:g}: eq 12 needs β/α > 1")
    alpha = math.log(k) / ((k - 1.0) * rise_time)
    return alpha, k * alpha


def blast_pressure(t, peak_pressure: float, rise_time: float, beta_over_alpha: float):
    """P(t) of eq 12 [Pa]: P0 (e^{−αt} − e^{−βt}) / (e^{−αt0} − e^{−βt0}), zero at t = 0, P0 at
    the rise time t0 (its peak), then decaying as e^{−αt}. Zero before t = 0."""
    alpha, beta = decay_rates(rise_time, beta_over_alpha)
    t = np.asarray(t, float)
    norm = math.exp(-alpha * rise_time) - math.exp(-beta * rise_time)
    p = peak_pressure * (np.exp(-alpha * t) - np.exp(-beta * t)) / norm
    return np.where(t > 0.0, p, 0.0)


def wall_layer(x: np.ndarray, centre, radius: float, spacing: float) -> np.ndarray:
    """Indices of the points in the wall layer R ≤ |x − c| < R + Δx of a hole."""
    r = np.hypot(x[:, 0] - centre[0], x[:, 1] - centre[1])
    return np.flatnonzero((r >= radius) & (r < radius + spacing))


def wall_force_per_pascal(x: np.ndarray, vol: np.ndarray, points: np.ndarray, centre, radius: float,
                          thickness: float) -> np.ndarray:
    """Body force per unit pressure [N/m³ per Pa] on the wall layer ``points``: radially outward,
    of magnitude 2πR h / V_layer, so that Σ |b| V = P × 2πR h."""
    d = x[points, :2] - np.asarray(centre, float)[None, :]
    n = d / np.linalg.norm(d, axis=1)[:, None]
    out = np.zeros((len(points), 3))
    out[:, :2] = n * (2.0 * math.pi * radius * thickness / vol[points].sum())
    return out


@dataclass(frozen=True)
class PressureLoad:
    """A pressure history P(t) [Pa] acting on the points ``points`` as the body force
    P(t) × ``force_per_pascal`` [N/m³]."""

    points: np.ndarray
    force_per_pascal: np.ndarray
    peak_pressure: float
    rise_time: float
    beta_over_alpha: float

    def pressure(self, t: float) -> float:
        return float(blast_pressure(t, self.peak_pressure, self.rise_time, self.beta_over_alpha))

    def add_body_force(self, t: float, out: np.ndarray) -> None:
        """out[points] += P(t) × force_per_pascal."""
        out[self.points] += self.pressure(t) * self.force_per_pascal
