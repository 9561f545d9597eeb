"""Blocks from CAD files (``dem.blocks[].shape: mesh``): the solid bounded by a closed triangle
surface (fcm_fsi/geometry/surface.py) as one rigid block.

Mass, centre of mass and inertia are the polyhedron's with the material's density (divergence
theorem, exact for the polyhedron), not the spheres'. The contact spheres, all of the block's
``radius`` r, sit on a cubic lattice in the file's frame whose spacing a is at most ``spacing``
(default 2r) and whose outermost nodes lie r inside the bounding box's faces (as a box block's
spheres: a box read from a file gets a box block's spheres on its faces). The spheres kept are
those whose centres are at a depth d below the surface with r ≤ d < r + a: they lie inside the
solid, touch its faces where a lattice layer meets them at depth r, and form a skin at least
one lattice layer thick (a slab of thickness a holds a lattice point in every direction), so
the contact surface has no hole wider than the lattice. Parts of the solid thinner than 2r get
no sphere. Interior nodes are left out: only the skin makes contact.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..config.dem import BlockConfig
from ..config.loader import ConfigError
from ..geometry.surface import ClosedSurface, MassProperties, SurfaceError, mass_properties, read_surface
from ..geometry.surface_distance import signed_distance
from .bodies import BlockTemplate


@dataclass(frozen=True)
class MeshBlock:
    """A block of shape mesh: its ``surface`` and ``properties`` in the file's frame (scaled,
    [m]) and its ``template`` (principal frame; ``template.R_body``: principal → file frame)."""

    surface: ClosedSurface
    properties: MassProperties
    template: BlockTemplate


def block_surface(b: BlockConfig, key: str) -> ClosedSurface:
    """The closed surface of block ``b`` (its file × scale); a ConfigError naming ``key``
    (e.g. ``dem.blocks[3]``), the file and the problem when it cannot be used."""
    try:
        return read_surface(b.file, b.scale)
    except SurfaceError as err:
        raise ConfigError(f"key '{key}.file' = {b.file!r}: {err}") from None


def mesh_block(b: BlockConfig, density: float, key: str = "dem.blocks[]") -> MeshBlock:
    """The surface, mass properties and template of block ``b`` of ``density`` [kg/m³]
    (cached: the case builds it more than once)."""
    return _mesh_block(b, float(density), key)


@lru_cache(maxsize=32)
def _mesh_block(b: BlockConfig, density: float, key: str) -> MeshBlock:
    surface = block_surface(b, key)
    props = mass_properties(surface, density)
    spacing = 2.0 * b.radius if b.spacing is None else b.spacing
    centres = skin_sphere_centres(surface, b.radius, spacing)
    if len(centres) == 0:
        extent = np.ptp(surface.vertices, axis=0)
        raise ConfigError(f"key '{key}.radius' = {b.radius:g} m: no contact sphere of that radius fits inside the "
                          f"solid of {b.file!r} (extent {extent.round(4).tolist()} m)")
    w, V = np.linalg.eigh(props.inertia)
    if np.linalg.det(V) < 0:
        V[:, 2] *= -1
    template = BlockTemplate(props.mass, w, (centres - props.centre) @ V, np.full(len(centres), float(b.radius)), V,
                             props.centre)
    return MeshBlock(surface, props, template)


def skin_sphere_centres(surface: ClosedSurface, radius: float, spacing: float) -> np.ndarray:
    """Centres (n, 3) [m] of the contact spheres of ``radius`` [m] in the solid's skin: the nodes
    of the lattice of spacing ≤ ``spacing`` (module docstring) at depth d, r ≤ d < r + a."""
    axes = lattice_axes(surface.vertices.min(axis=0) + radius, surface.vertices.max(axis=0) - radius, spacing)
    step = max((ax[1] - ax[0]) if len(ax) > 1 else 0.0 for ax in axes)
    nodes = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    depth = -signed_distance(np.ascontiguousarray(nodes), np.ascontiguousarray(surface.corners))
    tol = 1e-9 * float(np.ptp(surface.vertices, axis=0).max())
    return nodes[(depth >= radius - tol) & (depth < radius + max(step, tol))]


def lattice_axes(lo, hi, spacing: float) -> list[np.ndarray]:
    """Per axis, the sphere lattice's coordinates [m]: from ``lo`` to ``hi`` in equal steps
    ≤ ``spacing`` (one node in the middle where hi ≤ lo)."""
    axes = []
    for a, b in zip(lo, hi):
        n = int(np.ceil((b - a) / spacing * (1 - 1e-6))) + 1 if b > a else 1     # a float32 file's ties
        axes.append(np.linspace(a, b, n) if b > a else np.array([0.5 * (a + b)]))
    return axes
