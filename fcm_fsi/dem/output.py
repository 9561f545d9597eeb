"""DEM output: spheres as VTK PolyData (.vtp, binary inline) + a .pvd time collection for
ParaView (checkpoints: simulation/dem_model.py through the shared io/checkpoint.py).

ParaView: open ``spheres.pvd``, apply the *Glyph* filter (glyph type Sphere, scale array
``radius``, scale factor 2 — ParaView's unit sphere glyph has radius 0.5) and colour by
``block``.
"""
from __future__ import annotations

import base64
from pathlib import Path

import numpy as np

from .state import DEMState


def _b64(a: np.ndarray) -> str:
    raw = np.ascontiguousarray(a).tobytes()
    return base64.b64encode(np.uint32(len(raw)).tobytes() + raw).decode("ascii")


def _array(name: str, a: np.ndarray, ncomp: int) -> str:
    vt = {np.dtype(np.float64): "Float64", np.dtype(np.int64): "Int64", np.dtype(np.float32): "Float32"}[a.dtype]
    return (f'<DataArray type="{vt}" Name="{name}" NumberOfComponents="{ncomp}" format="binary">'
            f"{_b64(a)}</DataArray>")


def write_vtp(path: Path, state: DEMState, extra: dict[str, np.ndarray] | None = None) -> None:
    """One PolyData file: a vertex per sphere with radius, block id and velocity, and the
    per-sphere arrays of ``extra`` (name → (ns,) or (ns, 3))."""
    ns = state.ns
    vel = state.vel[state.sph_block] + np.cross(state.omega[state.sph_block],
                                                  state.sph_pos - state.pos[state.sph_block])
    conn = np.arange(ns, dtype=np.int64)
    xml = ['<?xml version="1.0"?>',
           '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt32">',
           "<PolyData>", f'<Piece NumberOfPoints="{ns}" NumberOfVerts="{ns}" NumberOfLines="0" '
           'NumberOfStrips="0" NumberOfPolys="0">',
           "<PointData Scalars=\"radius\">", _array("radius", state.sph_radius, 1),
           _array("block", state.sph_block.astype(np.int64), 1), _array("velocity", vel, 3),
           _array("material", state.sph_material.astype(np.int64), 1),
           *(_array(k, np.asarray(v), 1 if np.ndim(v) == 1 else 3) for k, v in (extra or {}).items()),
           "</PointData>",
           "<Points>", _array("Points", state.sph_pos, 3), "</Points>",
           "<Verts>", _array("connectivity", conn, 1), _array("offsets", conn + 1, 1), "</Verts>",
           "</Piece>", "</PolyData>", "</VTKFile>"]
    Path(path).write_text("\n".join(xml))


def write_pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    """ParaView collection of (time, relative file name)."""
    rows = "\n".join(f'<DataSet timestep="{t!r}" group="" part="0" file="{f}"/>' for t, f in entries)
    Path(path).write_text('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n'
                          f"<Collection>\n{rows}\n</Collection>\n</VTKFile>\n")


def read_pvd(path: Path, t_max: float = np.inf) -> list[tuple[float, str]]:
    """The (time, file) entries of a collection written by :func:`write_pvd` up to ``t_max``
    [s] (a restart continues the collection from its checkpoint); [] if there is none."""
    import re
    path = Path(path)
    if not path.exists():
        return []
    rows = re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', path.read_text())
    limit = t_max + 1e-12 * max(abs(t_max), 1.0) if np.isfinite(t_max) else np.inf
    return [(float(t), f) for t, f in rows if float(t) <= limit]
