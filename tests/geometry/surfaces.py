"""Closed test surfaces: a box of 12 triangles and gmsh's triangulation of a sphere, written to
files with meshio (STL ASCII and binary, OBJ, gmsh)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

#: the unit cube's faces as corner indices (x + 2y + 4z), counter-clockwise seen from outside
CUBE_QUADS = ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5))


def box_surface(lo=(0.0, 0.0, 0.0), hi=(1.0, 1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and outward triangles (12, 3) of the box lo..hi [m]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corner = np.array([[k & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], float)
    tri = [(q[0], q[1], q[2]) for q in CUBE_QUADS] + [(q[0], q[2], q[3]) for q in CUBE_QUADS]
    return lo + corner * (hi - lo), np.array(tri, np.int64)


def sphere_surface(radius: float, size: float) -> tuple[np.ndarray, np.ndarray]:
    """gmsh's triangulation (mesh size ``size``) of the sphere of ``radius`` about the origin:
    vertices on the sphere, triangles (orientation as gmsh gives it)."""
    import gmsh
    gmsh.initialize(["-v", "0"])
    try:
        gmsh.model.add("sphere")
        gmsh.model.occ.addSphere(0.0, 0.0, 0.0, radius)
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, _, nodes = gmsh.model.mesh.getElements(2)
        index = np.zeros(int(tags.max()) + 1, np.int64)
        index[tags.astype(np.int64)] = np.arange(len(tags))
        tri = index[np.concatenate(nodes).astype(np.int64)].reshape(-1, 3)
        return np.asarray(coords).reshape(-1, 3), tri
    finally:
        gmsh.finalize()


def write_surface(path: Path, vertices, triangles, **kwargs) -> Path:
    """The surface as a file meshio writes by its suffix (``binary=True`` for a binary STL)."""
    import meshio
    meshio.write(str(path), meshio.Mesh(np.asarray(vertices, float), [("triangle", np.asarray(triangles))]), **kwargs)
    return path
