"""Discrete elements: clumped-sphere rigid blocks (section ``dem``; SPEC §2). Owned by the DEM."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError
from .structure import CohesiveConfig, StructureConfig

Vec3 = tuple[float, float, float]
DofMode = Literal["free", "force", "velocity", "displacement"]


@dataclass(frozen=True, kw_only=True)
class MaterialConfig:
    """Contact parameters of one material (paper eqs 18–20; normal = tangential by default)."""

    name: str = param(doc="material name referred to by blocks and walls")
    stiffness: float = param(unit="N/m", doc="normal spring constant K", gt=0)
    tangential_ratio: float = param(1.0, doc="tangential / normal spring constant (the paper uses 1)", gt=0, le=10)
    restitution: float = param(unit="-", doc="restitution coefficient e; the dashpot follows from eq 20", gt=0, le=1)
    friction_angle: float = param(unit="deg", doc="friction angle φ, μ = tan φ", ge=0, lt=90)
    density: float = param(2500.0, unit="kg/m^3", doc="solid density of blocks made of this material", gt=0)

    @property
    def mu(self) -> float:
        return math.tan(math.radians(self.friction_angle))


@dataclass(frozen=True, kw_only=True)
class BlockConfig:
    """One rigid block: a solid box tiled by surface spheres, one sphere, a clump, or a solid
    read from a CAD surface file (docs/dem.md, "Structures from CAD files")."""

    shape: Literal["box", "sphere", "clump", "mesh"] = param(doc="box: solid box with spheres on its surface (mass "
                                                                 "from the box); sphere: one sphere; clump: mass from "
                                                                 "its spheres; mesh: the solid bounded by the closed "
                                                                 "surface in file (mass from it), spheres in its skin")
    material: str = param(doc="material name")
    position: Vec3 = param(unit="m", doc="centre of mass (box, sphere) or origin of the clump's sphere coordinates "
                                         "or of the mesh file's coordinates")
    size: Vec3 | None = param(None, unit="m", doc="box edge lengths (shape box)", gt=0)
    radius: float | None = param(None, unit="m", doc="sphere radius (shape sphere) or surface-sphere radius (shape box, "
                                                     "mesh)", gt=0)
    spacing: float | None = param(None, unit="m", doc="largest surface-sphere centre spacing on a box edge, or the "
                                                      "sphere lattice's spacing of shape mesh (default 2·radius)", gt=0)
    file: str = param("", doc="closed surface file of shape mesh: STL (ASCII or binary), OBJ, gmsh .msh or another "
                              "format meshio reads (relative to the case file)")
    scale: float = param(1.0, doc="factor from the file's coordinates to metres (shape mesh)", gt=0)
    fill: Literal["clump", "bonded_grid"] = param("clump", doc="shape mesh: clump: one rigid block, its contact "
                                                               "spheres on a lattice in the solid's skin; "
                                                               "bonded_grid: the solid cut by a grid of cells of "
                                                               "grid_size into blocks (each a clump of its skin's "
                                                               "spheres) bonded by dem.cohesive on the faces they "
                                                               "share")
    grid_size: float | None = param(None, unit="m", doc="fill bonded_grid: edge of the grid's cubic cells, from the "
                                                        "lower corner of the solid's bounding box (at least "
                                                        "2·radius)", gt=0)
    sdf_spacing: float | None = param(None, unit="m", doc="shape mesh: node spacing of the signed-distance grid the "
                                                          "fluid sees (default radius/2)", gt=0)
    sdf_margin: float | None = param(None, unit="m", doc="shape mesh: how far that grid reaches beyond the surface; "
                                                         "must be at least the level-set band coupling.band (default "
                                                         "a quarter of the solid's largest extent)", gt=0)
    spheres: tuple[tuple[float, float, float, float], ...] = param((), unit="m", doc="clump spheres as (x, y, z, r) "
                                                                                     "relative to position")
    axis: Vec3 = param((0.0, 0.0, 1.0), doc="rotation axis of the initial orientation")
    angle: float = param(0.0, unit="deg", doc="initial rotation about axis")
    velocity: Vec3 = param((0.0, 0.0, 0.0), unit="m/s", doc="initial velocity")
    omega: Vec3 = param((0.0, 0.0, 0.0), unit="rad/s", doc="initial angular velocity (world frame)")
    fixed: bool = param(False, doc="block never moves (acts as a wall)")
    bonded: bool = param(False, doc="bond this box by the cohesive law dem.cohesive to every other bonded box it "
                                    "shares a face with (boxes not rotated, angle 0)")

    def __post_init__(self) -> None:
        if self.shape == "box" and (self.size is None or self.radius is None):
            raise ConfigError("key 'dem.blocks[].size' and 'radius' are required for shape 'box'")
        if self.shape == "sphere" and self.radius is None:
            raise ConfigError("key 'dem.blocks[].radius' is required for shape 'sphere'")
        if self.shape == "mesh" and (not self.file or self.radius is None):
            raise ConfigError("key 'dem.blocks[].file' and 'radius' are required for shape 'mesh'")
        if self.shape == "clump" and not self.spheres:
            raise ConfigError("key 'dem.blocks[].spheres' must list at least one (x, y, z, r) for shape 'clump'")
        if any(s[3] <= 0 for s in self.spheres):
            raise ConfigError(f"key 'dem.blocks[].spheres' radii must be > 0, got {self.spheres}")
        if self.shape == "box" and self.size is not None and min(self.size) < 2 * self.radius:
            raise ConfigError(f"key 'dem.blocks[].size' = {self.size} is thinner than 2·radius = {2 * self.radius}")
        if sum(a * a for a in self.axis) == 0:
            raise ConfigError("key 'dem.blocks[].axis' must not be the zero vector")
        if self.fill == "bonded_grid" and (self.shape != "mesh" or self.grid_size is None):
            raise ConfigError(f"key 'dem.blocks[].fill' = 'bonded_grid' needs shape 'mesh' and a grid_size; got shape "
                              f"{self.shape!r}, grid_size {self.grid_size}")
        if self.grid_size is not None and self.fill != "bonded_grid":
            raise ConfigError("key 'dem.blocks[].grid_size' is used only with fill 'bonded_grid'")
        if self.grid_size is not None and self.radius is not None and self.grid_size < 2 * self.radius:
            raise ConfigError(f"key 'dem.blocks[].grid_size' = {self.grid_size:g} m is below 2·radius = "
                              f"{2 * self.radius:g} m: no contact sphere fits in a cell")
        if self.bonded and (self.shape != "box" or self.angle % 360.0 != 0.0):
            raise ConfigError(f"key 'dem.blocks[].bonded' needs an unrotated box (shape 'box', angle 0); "
                              f"got shape {self.shape!r}, angle {self.angle}")


@dataclass(frozen=True, kw_only=True)
class GeneratorConfig:
    """Many copies of one block template on a jittered lattice inside a region, with
    random orientations (reproducible for a seed)."""

    block: BlockConfig = param(doc="template block (its position is ignored)")
    count: int = param(unit="-", doc="number of blocks", ge=1)
    region_min: Vec3 = param(unit="m", doc="lower corner of the fill region")
    region_max: Vec3 = param(unit="m", doc="upper corner of the fill region")
    seed: int = param(0, doc="random seed (orientations and jitter)", ge=0)
    random_orientation: bool = param(True, doc="draw uniformly random orientations")

    def __post_init__(self) -> None:
        if any(a >= b for a, b in zip(self.region_min, self.region_max)):
            raise ConfigError(f"key 'dem.generators[].region_min' {self.region_min} must be below region_max {self.region_max}")
        if self.block.fill == "bonded_grid":
            raise ConfigError("key 'dem.generators[].block.fill' = 'bonded_grid': generated blocks are single "
                              "blocks; put a bonded structure in dem.blocks")


@dataclass(frozen=True, kw_only=True)
class WallConfig:
    """A static wall: a half-space, the inside of a box, or a triangulated surface."""

    kind: Literal["plane", "box", "mesh"] = param(doc="plane: half-space; box: closed container (its 6 inner faces); "
                                                      "mesh: triangles")
    material: str = param(doc="material name")
    point: Vec3 = param((0.0, 0.0, 0.0), unit="m", doc="a point on the plane (kind plane)")
    normal: Vec3 = param((0.0, 0.0, 1.0), doc="plane normal pointing into the domain (kind plane)")
    lo: Vec3 = param((0.0, 0.0, 0.0), unit="m", doc="lower corner (kind box)")
    hi: Vec3 = param((1.0, 1.0, 1.0), unit="m", doc="upper corner (kind box)")
    open_top: bool = param(False, doc="box without its upper (+z) face")
    vertices: tuple[Vec3, ...] = param((), unit="m", doc="mesh vertices (kind mesh)")
    triangles: tuple[tuple[int, int, int], ...] = param((), doc="mesh triangles as vertex indices (kind mesh)", ge=0)
    remove_at: float | None = param(None, unit="s", doc="the wall disappears at this time (a gate); null = never", ge=0)

    def __post_init__(self) -> None:
        if self.kind == "plane" and sum(a * a for a in self.normal) == 0:
            raise ConfigError("key 'dem.walls[].normal' must not be the zero vector")
        if self.kind == "box" and any(a >= b for a, b in zip(self.lo, self.hi)):
            raise ConfigError(f"key 'dem.walls[].lo' {self.lo} must be below hi {self.hi}")
        if self.kind == "mesh":
            if not self.triangles:
                raise ConfigError("key 'dem.walls[].triangles' must list triangles for kind 'mesh'")
            if max(max(t) for t in self.triangles) >= len(self.vertices):
                raise ConfigError(f"key 'dem.walls[].triangles' refers to a vertex >= {len(self.vertices)}")


@dataclass(frozen=True, kw_only=True)
class ControlConfig:
    """A controlled block (tutorial §3): per world DOF x, y, z, rx, ry, rz a mode and value
    (force N / torque N m; velocity m/s, rad/s; displacement m, rad reached over ``ramp``)."""

    block: int = param(doc="index of the block in dem.blocks (generated blocks follow)", ge=0)
    modes: tuple[DofMode, DofMode, DofMode, DofMode, DofMode, DofMode] = param(doc="mode of x, y, z, rx, ry, rz")
    values: tuple[float, float, float, float, float, float] = param((0.0,) * 6, doc="value per DOF (unit by mode)")
    ramp: float = param(0.0, unit="s", doc="displacement mode: time to reach the value linearly (0 = at once)", ge=0)


@dataclass(frozen=True, kw_only=True)
class DEMConfig:
    """Rigid blocks made of clumped spheres with spring–dashpot–slider contact."""

    dt: float = param(unit="s", doc="DEM time step", gt=0)
    dt_safety: float = param(0.2, doc="largest allowed dt / Δt_cr (tutorial §6 recommends ~0.1)", gt=0, le=1)
    gravity: Vec3 = param((0.0, 0.0, -9.81), unit="m/s^2", doc="gravitational acceleration")
    clip_normal: bool = param(True, doc="forbid attractive normal contact force (restitution then exceeds e, see docs/dem.md)")
    skin: float | None = param(None, unit="m", doc="Verlet-list skin (default 0.3 × smallest radius)", gt=0)
    materials: tuple[MaterialConfig, ...] = param(doc="contact materials")
    blocks: tuple[BlockConfig, ...] = param((), doc="individual blocks")
    generators: tuple[GeneratorConfig, ...] = param((), doc="generated blocks (appended after blocks)")
    walls: tuple[WallConfig, ...] = param((), doc="static walls")
    controls: tuple[ControlConfig, ...] = param((), doc="controlled blocks")
    structure: StructureConfig | None = param(None, doc="a bonded-block building from the structure builder (its "
                                                        "blocks follow blocks and generators)")
    cohesive: CohesiveConfig | None = param(None, doc="cohesive law of the bonds between the structure's blocks and "
                                                      "between bonded blocks (required with either)")
    ledger_every: int = param(100, unit="steps", doc="DEM-only runs: energy-ledger and force–displacement CSV "
                                                     "row every this many DEM steps (coupled runs keep no ledger)",
                            ge=1)

    def __post_init__(self) -> None:
        names = [m.name for m in self.materials]
        if not names:
            raise ConfigError("key 'dem.materials' must define at least one material")
        if len(set(names)) != len(names):
            raise ConfigError(f"key 'dem.materials' has duplicate names {names}")
        used = [(f"dem.blocks[{i}].material", b.material) for i, b in enumerate(self.blocks)]
        used += [(f"dem.generators[{i}].block.material", g.block.material) for i, g in enumerate(self.generators)]
        used += [(f"dem.walls[{i}].material", w.material) for i, w in enumerate(self.walls)]
        if self.structure is not None:
            used.append(("dem.structure.material", self.structure.material))
            if self.cohesive is None:
                raise ConfigError("key 'dem.cohesive' is required when dem.structure is given")
        bonded = [i for i, b in enumerate(self.blocks) if b.bonded or b.fill == "bonded_grid"]
        if bonded and self.cohesive is None:
            raise ConfigError(f"key 'dem.cohesive' is required when dem.blocks{bonded} are bonded")
        for key, name in used:
            if name not in names:
                raise ConfigError(f"key '{key}' = {name!r} is not a defined material ({', '.join(names)})")
        nblocks = len(self.blocks) + sum(g.count for g in self.generators)
        if nblocks == 0 and self.structure is None:
            raise ConfigError("key 'dem.blocks' / 'dem.generators': the case has no blocks")
        grids = any(b.fill == "bonded_grid" for b in self.blocks)   # their piece counts need the file
        for i, c in enumerate(self.controls):
            if c.block >= nblocks and not grids:
                raise ConfigError(f"key 'dem.controls[{i}].block' = {c.block} but there are {nblocks} blocks")

    def material_index(self, name: str) -> int:
        return [m.name for m in self.materials].index(name)
