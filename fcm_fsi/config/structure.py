"""Cohesive bonds (eq 28) and the building description of the structure builder.

Two sections meant to hang under ``dem``: ``dem.cohesive`` (:class:`CohesiveConfig`) and
``dem.structure`` (:class:`StructureConfig`). See docs/cohesive.md for the physics and an
example. Coordinates: x is the flow direction (water arrives from −x), z is up.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError

Side = Literal["xmin", "xmax", "ymin", "ymax"]


@dataclass(frozen=True, kw_only=True)
class CohesiveConfig:
    """Polynomial cohesive law on faces shared by adjacent blocks (paper eq 28)."""

    sigma_c: float = param(unit="Pa", doc="peak normal traction σ_c of eq 28", gt=0)
    delta_f: float = param(unit="m", doc="normal opening δ_f at complete failure (peak at δ_f/3)", gt=0)
    delta_tc: float | None = param(None, unit="m", doc="tangential opening that counts as δ_f in the mixed-mode "
                                                       "opening λ = √((δn/δ_f)² + (δt/δ_tc)²); null = δ_f", gt=0)
    mode: Literal["reversible", "damage"] = param("reversible", doc="unloading: 'reversible' along eq 28 (the "
                                                                    "paper), 'damage' along the secant to the origin "
                                                                    "from the largest λ reached")
    penalty_factor: float = param(1.0, doc="compression penalty stiffness / initial stiffness 27/4·σ_c/δ_f (1 = same "
                                           "slope on both sides of δ = 0)", gt=0, le=1000)
    points_per_edge: int = param(2, doc="Gauss points per face edge; a face carries points_per_edge² integration "
                                        "points", ge=1, le=8)


@dataclass(frozen=True, kw_only=True)
class OpeningConfig:
    """A door or window cut out of one perimeter wall panel."""

    storey: int = param(doc="storey index, 0 = ground floor", ge=0)
    side: Side = param(doc="wall side: xmin (front, facing the incoming water), xmax, ymin, ymax")
    bay: int = param(doc="bay index along that side, counted from the lower coordinate", ge=0)
    offset: float = param(unit="m", doc="distance from the panel's start (the column face) to the opening", ge=0)
    width: float = param(unit="m", doc="opening width", gt=0)
    sill: float = param(0.0, unit="m", doc="height of the opening's bottom above the panel's bottom", ge=0)
    height: float = param(unit="m", doc="opening height", gt=0)


@dataclass(frozen=True, kw_only=True)
class StructureConfig:
    """A frame building: columns on a grid, perimeter walls between them, a slab per storey.

    Members are boxes cut into blocks no longer than ``block_size`` (opening edges are cut
    lines too); every block is a solid box of ``density`` carrying spheres of
    ``sphere_radius`` on its surface only; every pair of blocks sharing a face is bonded.
    """

    origin: tuple[float, float, float] = param((0.0, 0.0, 0.0), unit="m", doc="position of the first column's grid "
                                                                              "point at ground level")
    storeys: int = param(doc="number of storeys", ge=1, le=50)
    storey_height: float = param(unit="m", doc="floor-to-floor height (columns + slab)", gt=0)
    bays_x: tuple[float, ...] = param(unit="m", doc="column spacings along x", gt=0)
    bays_y: tuple[float, ...] = param(unit="m", doc="column spacings along y", gt=0)
    column: tuple[float, float] = param(unit="m", doc="column cross-section (x, y)", gt=0)
    wall_thickness: float = param(unit="m", doc="perimeter wall thickness, centred on the grid line", gt=0)
    walls: tuple[Side, ...] = param(("xmin", "xmax", "ymin", "ymax"), doc="sides that carry walls")
    slab_thickness: float = param(unit="m", doc="floor/roof slab thickness; the slab covers the footprint including "
                                                "columns", gt=0)
    openings: tuple[OpeningConfig, ...] = param((), doc="doors and windows")
    block_size: float = param(unit="m", doc="largest block edge; members are cut into equal blocks no longer than this", gt=0)
    sphere_radius: float = param(unit="m", doc="radius of the surface spheres (every block edge must be >= 2 radii)", gt=0)
    material: str = param(doc="material name in dem.materials (contact parameters of the spheres)")
    density: float | None = param(None, unit="kg/m³", doc="density of the solid blocks (mass and inertia come from "
                                                          "the box); null = the material's density", gt=0)
    foundation: float = param(0.0, unit="m", doc="thickness of a fixed foundation slab under the footprint, its top "
                                                 "at the origin's z; every block standing on it is bonded to it by "
                                                 "dem.cohesive, so the building is anchored and its ground-floor "
                                                 "joints carry the base shear (without it the building stands loose "
                                                 "on the ground and slides as a whole once the lateral load passes "
                                                 "friction × weight). The foundation never moves, comes after the "
                                                 "building's blocks, and the fluid does not see it (it lies below "
                                                 "the ground); 0 = none. At least 2 sphere radii", ge=0)

    def __post_init__(self) -> None:
        if not self.bays_x or not self.bays_y:
            raise ConfigError("key 'structure.bays_x'/'bays_y' needs at least one bay each")
        cx, cy = self.column
        if self.wall_thickness > min(cx, cy):
            raise ConfigError(f"key 'structure.wall_thickness' = {self.wall_thickness} must not exceed "
                              f"the column size {min(cx, cy)} (walls frame into the columns)")
        if self.slab_thickness >= self.storey_height:
            raise ConfigError(f"key 'structure.slab_thickness' = {self.slab_thickness} must be below "
                              f"storey_height = {self.storey_height}")
        if min(self.bays_x + self.bays_y) <= max(cx, cy):
            raise ConfigError("key 'structure.bays_x'/'bays_y': every bay must be longer than the column")
        if 0.0 < self.foundation < 2 * self.sphere_radius:
            raise ConfigError(f"key 'structure.foundation' = {self.foundation} m: allowed 0 (none) or at least "
                              f"two sphere radii, {2 * self.sphere_radius:g} m")
        if len(set(self.walls)) != len(self.walls):
            raise ConfigError(f"key 'structure.walls' = {list(self.walls)} repeats a side")
        for i, op in enumerate(self.openings):
            key = f"structure.openings[{i}]"
            if op.storey >= self.storeys:
                raise ConfigError(f"key '{key}.storey' = {op.storey}: the building has {self.storeys} storeys")
            if op.side not in self.walls:
                raise ConfigError(f"key '{key}.side' = {op.side!r} has no wall (walls: {list(self.walls)})")
            bays = self.bays_x if op.side in ("ymin", "ymax") else self.bays_y
            col = cx if op.side in ("ymin", "ymax") else cy
            if op.bay >= len(bays):
                raise ConfigError(f"key '{key}.bay' = {op.bay}: side {op.side} has {len(bays)} bays")
            panel = bays[op.bay] - col
            if op.offset + op.width > panel + 1e-12:
                raise ConfigError(f"key '{key}': offset + width = {op.offset + op.width:g} m exceeds the "
                                  f"wall panel length {panel:g} m")
            clear = self.storey_height - self.slab_thickness
            if op.sill + op.height > clear + 1e-12:
                raise ConfigError(f"key '{key}': sill + height = {op.sill + op.height:g} m exceeds the "
                                  f"clear storey height {clear:g} m")
