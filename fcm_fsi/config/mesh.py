"""The fixed background mesh (section ``mesh``)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError

#: what the planes of the mesh box were called before they were named by axis, in the order of
#: :func:`box_boundary_names` (x-lo, x-hi, y-lo, y-hi, z-lo, z-hi)
FORMER_BOX_NAMES = ("left", "right", "bottom", "top", "front", "back")


def box_boundary_names(dim: int) -> tuple[str, ...]:
    """The boundaries of a ``dim``-D mesh, named by axis and end, in the order of their facet
    tags 1, 2, …: ``xmin xmax ymin ymax`` (2D) and ``zmin zmax`` (3D): the planes
    x = mesh.lower[0], x = mesh.upper[0], and so on."""
    return tuple(f"{axis}{end}" for axis in "xyz"[:dim] for end in ("min", "max"))


def former_name_message(name: str, dim: int) -> str | None:
    """Why the former box boundary name ``name`` (``left`` … ``back``) is refused in a
    ``dim``-D mesh, with its axis name; None for any other name."""
    if name not in FORMER_BOX_NAMES:
        return None
    axis_name = box_boundary_names(3)[FORMER_BOX_NAMES.index(name)]
    if axis_name not in box_boundary_names(dim):
        return (f"boundaries are named by axis now; {name!r} was the 3D {axis_name!r}, and a {dim}D mesh has "
                f"{', '.join(box_boundary_names(dim))}")
    return f"boundaries are named by axis now; in {dim}D {name!r} is {axis_name!r}"


@dataclass(frozen=True, kw_only=True)
class RefineZone:
    """A box where gmsh uses a smaller cell size (e.g. near a free surface)."""

    lower: tuple[float, ...] = param(unit="m", doc="lower corner of the zone")
    upper: tuple[float, ...] = param(unit="m", doc="upper corner of the zone")
    size: float = param(unit="m", doc="cell size inside the zone", gt=0)
    grading: float | None = param(None, doc="outside the zone the cell size grows by this much per metre of "
                                  "distance from it, up to mesh.size (unset: it jumps to mesh.size at the zone's "
                                  "edge; a jump of 10× or more leaves badly shaped cells there)", gt=0, le=10)


@dataclass(frozen=True, kw_only=True)
class StructureBand:
    """Cells graded away from the structure: ``size`` at the faces of the DEM blocks (as the
    fluid sees them, at their starting poses), growing by ``grading`` per metre of distance,
    up to ``mesh.size``. A band, not a box: the cell count grows with the blocks' face area,
    not with the volume around them."""

    size: float = param(unit="m", doc="cell size at the blocks' faces", gt=0)
    grading: float = param(0.3, doc="growth of the cell size per metre of distance from the faces (dh/dd): "
                           "0.3 doubles it about every 3 cells", gt=0, le=1)


@dataclass(frozen=True, kw_only=True)
class MeshConfig:
    """Structured rectangle/box meshes from dolfinx, or gmsh meshes (generated and cached, or a file)."""

    kind: Literal["rectangle", "box", "gmsh_box", "gmsh_disk", "gmsh_file"] = param(doc="rectangle/box: structured "
                                                                                        "simplices; gmsh_box: "
                                                                                        "unstructured gmsh "
                                                                                        "box/rectangle with refine "
                                                                                        "zones; gmsh_disk: "
                                                                                        "unstructured disk (2D) of "
                                                                                        "`radius` centred in "
                                                                                        "lower..upper; gmsh_file: a "
                                                                                        ".msh file")
    lower: tuple[float, ...] = param((0.0, 0.0), unit="m", doc="lower corner of the domain (2 or 3 numbers)")
    upper: tuple[float, ...] = param((1.0, 1.0), unit="m", doc="upper corner of the domain (2 or 3 numbers)")
    cells: tuple[int, ...] = param((32, 32), doc="cells per direction for rectangle/box", ge=1)
    size: float = param(0.05, unit="m", doc="target cell size for gmsh_box and gmsh_disk", gt=0)
    radius: float = param(1.0, unit="m", doc="gmsh_disk radius (the disk is centred in the lower..upper box)", gt=0)
    refine: tuple[RefineZone, ...] = param(default_factory=tuple, doc="gmsh_box refine zones")
    structure_band: StructureBand | None = param(None, doc="gmsh_box/gmsh_disk in a case with dem blocks: "
                                                 "cells graded from a size at the blocks' faces (a coupled case only)")
    file: str = param("", doc="path of a gmsh .msh file for gmsh_file (relative to the case file)")
    diagonal: Literal["right", "left", "crossed"] = param("right", doc="triangle diagonal for rectangle meshes")

    def __post_init__(self) -> None:
        if len(self.lower) not in (2, 3) or len(self.upper) != len(self.lower):
            raise ConfigError("key 'mesh.lower'/'mesh.upper' must both have 2 (2D) or 3 (3D) entries")
        if any(u <= l for l, u in zip(self.lower, self.upper)):
            raise ConfigError(f"key 'mesh.upper' = {list(self.upper)} must exceed mesh.lower = {list(self.lower)} "
                              "in every direction")
        if self.kind in ("rectangle", "box") and len(self.cells) != len(self.lower):
            raise ConfigError(f"key 'mesh.cells' must have {len(self.lower)} entries, one per direction")
        if self.kind == "gmsh_disk" and self.dim != 2:
            raise ConfigError("key 'mesh.kind' = 'gmsh_disk' is 2D: give 2 entries in mesh.lower/upper")
        if self.kind == "gmsh_file" and not self.file:
            raise ConfigError("key 'mesh.file' is required when mesh.kind = 'gmsh_file'")
        band = self.structure_band
        if band is not None:
            if self.kind not in ("gmsh_box", "gmsh_disk"):
                raise ConfigError(f"key 'mesh.structure_band' needs mesh.kind gmsh_box or gmsh_disk, not {self.kind!r}")
            if band.size >= self.size:
                raise ConfigError(f"key 'mesh.structure_band.size' = {band.size:g} m: allowed 0 < size < "
                                  f"mesh.size = {self.size:g} m")

    @property
    def dim(self) -> int:
        return len(self.lower)
