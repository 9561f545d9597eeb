"""Stabilized Navier–Stokes fluid (section ``fluid``; SPEC eqs 1–10). Owned by the fluid solver."""
from __future__ import annotations

from dataclasses import dataclass

from .fields import param


@dataclass(frozen=True, kw_only=True)
class FluidConfig:
    """Single- or two-phase incompressible Newtonian fluid."""

    density: float = param(1000.0, unit="kg/m^3", doc="density of the (liquid) fluid", gt=0)
    viscosity: float = param(1.0e-3, unit="Pa s", doc="dynamic viscosity of the (liquid) fluid", gt=0)
