"""Material points at the centroids of a gmsh tetrahedral mesh, each with its tetrahedron's
volume (seed §4): from a .msh file or from a box that gmsh meshes with a target size."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config.loader import ConfigError
from ..config.pd import PDParticlesConfig

#: gmsh's element type of the 4-node tetrahedron
TETRAHEDRON = 4


def tet_centroids_and_volumes(nodes: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (M, 3) [m] and volumes |det[b−a, c−a, d−a]|/6 (M,) [m³] of the tetrahedra ``tets``
    (M, 4) node indices into ``nodes`` (K, 3) [m]."""
    p = nodes[tets]
    a = p[:, 1] - p[:, 0]
    b = p[:, 2] - p[:, 0]
    c = p[:, 3] - p[:, 0]
    return p.mean(axis=1), np.abs(np.einsum("ij,ij->i", np.cross(a, b), c)) / 6.0


def local_spacing(x: np.ndarray, vol: np.ndarray, reach: float) -> np.ndarray:
    """h_i = (mean V_j over the points j within ``reach`` × V_i^(1/3) of i, i itself included)^(1/3)
    [m]: the spacing of a regular lattice with the cloud's local number density, so that a
    horizon factor × h holds about as many points as on the lattice. The mean over a
    neighbourhood (rather than the point's own V^(1/3)) keeps a sliver tetrahedron from giving
    its point a horizon with few neighbours; it still follows a graded mesh."""
    from .neighbours import bond_lists
    offsets, nbr = bond_lists(x, reach * np.cbrt(vol))
    owner = np.repeat(np.arange(len(x)), np.diff(offsets))
    total = np.bincount(owner, weights=vol[nbr], minlength=len(x)) + vol
    return np.cbrt(total / (np.diff(offsets) + 1))


def _tetrahedra_of_current_model() -> tuple[np.ndarray, np.ndarray]:
    """Nodes (K, 3) and tetrahedra (M, 4) of the gmsh model in the current session."""
    import gmsh
    tags, coords, _ = gmsh.model.mesh.getNodes()
    nodes = coords.reshape(-1, 3)
    index = np.full(int(tags.max()) + 1, -1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    tets = [index[conn.astype(np.int64)].reshape(-1, 4)
            for kind, _, conn in zip(*gmsh.model.mesh.getElements(3)) if kind == TETRAHEDRON]
    return nodes, (np.concatenate(tets) if tets else np.zeros((0, 4), np.int64))


def _gmsh_session(build) -> tuple[np.ndarray, np.ndarray]:
    import gmsh
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)          # the same mesh on every rank
        build(gmsh)
        return _tetrahedra_of_current_model()
    finally:
        gmsh.finalize()


def box_tetrahedra(lower, upper, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and tetrahedra of the box [``lower``, ``upper``] meshed by gmsh with edge ≈ ``size`` [m]."""
    def build(gmsh):
        gmsh.model.add("pd_box")
        gmsh.model.occ.addBox(*lower, *(b - a for a, b in zip(lower, upper)))
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
    return _gmsh_session(build)


def file_tetrahedra(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and tetrahedra of a gmsh .msh file."""
    def build(gmsh):
        gmsh.open(str(path))
    return _gmsh_session(build)


def tet_particles(cfg: PDParticlesConfig, case_dir: Path | None = None
                  ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Points (N, 3) [m] at the tetrahedra's centroids, their volumes (N,) [m³] and the bounding
    box (lower, upper) of the mesh. ``pd.particles.file`` is relative to ``case_dir`` (the case
    file's folder; None: the working directory)."""
    if cfg.file is not None:
        path = Path(cfg.file)
        if not path.is_absolute() and case_dir is not None:
            path = case_dir / path
        if not path.is_file():
            raise ConfigError(f"key 'pd.particles.file' = {cfg.file!r}: file not found ({path})")
        try:
            nodes, tets = file_tetrahedra(path)
        except Exception as err:                                 # gmsh raises a bare Exception
            raise ConfigError(f"key 'pd.particles.file' = {cfg.file!r}: gmsh cannot read {path}: {err}") from None
    else:
        nodes, tets = box_tetrahedra(cfg.lower, cfg.upper, cfg.size)
    if len(tets) == 0:
        raise ConfigError(f"key 'pd.particles': the mesh{'' if cfg.file is None else ' ' + repr(cfg.file)} has no "
                          "tetrahedra (gmsh element type 4)")
    x, vol = tet_centroids_and_volumes(nodes, tets)
    used = nodes[np.unique(tets)]
    return x, vol, (used.min(axis=0), used.max(axis=0))
