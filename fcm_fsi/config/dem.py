"""Discrete elements: clumped-sphere rigid blocks (section ``dem``; SPEC §2). Owned by the DEM."""
from __future__ import annotations

from dataclasses import dataclass

from .fields import param


@dataclass(frozen=True, kw_only=True)
class DEMConfig:
    """Rigid blocks made of clumped spheres with spring–dashpot–slider contact."""

    dt: float = param(unit="s", doc="DEM time step", gt=0)
