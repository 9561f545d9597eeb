"""Point clouds for ParaView: VTK PolyData (.vtp, binary inline, one vertex per point) and the
.pvd time collection that lists them. Used by the DEM's spheres and the peridynamic points."""
from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np


def _b64(a: np.ndarray) -> str:
    raw = np.ascontiguousarray(a).tobytes()
    return base64.b64encode(np.uint32(len(raw)).tobytes() + raw).decode("ascii")


def _array(name: str, a: np.ndarray, ncomp: int) -> str:
    vt = {np.dtype(np.float64): "Float64", np.dtype(np.int64): "Int64", np.dtype(np.float32): "Float32"}[a.dtype]
    return (f'<DataArray type="{vt}" Name="{name}" NumberOfComponents="{ncomp}" format="binary">'
            f"{_b64(a)}</DataArray>")


def write_points_vtp(path: Path, points: np.ndarray, point_data: dict[str, np.ndarray],
                     scalars: str | None = None) -> None:
    """One PolyData file: a vertex per row of ``points`` (n, 3) with the arrays of ``point_data``
    (name → (n,) or (n, 3); float64 or int64)."""
    n = len(points)
    conn = np.arange(n, dtype=np.int64)
    head = f'<PointData Scalars="{scalars}">' if scalars else "<PointData>"
    xml = ['<?xml version="1.0"?>',
           '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt32">',
           "<PolyData>", f'<Piece NumberOfPoints="{n}" NumberOfVerts="{n}" NumberOfLines="0" '
           'NumberOfStrips="0" NumberOfPolys="0">', head,
           *(_array(k, np.asarray(v), 1 if np.ndim(v) == 1 else 3) for k, v in point_data.items()),
           "</PointData>",
           "<Points>", _array("Points", np.ascontiguousarray(points, np.float64), 3), "</Points>",
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
    path = Path(path)
    if not path.exists():
        return []
    rows = re.findall(r'timestep="([^"]+)"[^>]*file="([^"]+)"', path.read_text())
    limit = t_max + 1e-12 * max(abs(t_max), 1.0) if np.isfinite(t_max) else np.inf
    return [(float(t), f) for t, f in rows if float(t) <= limit]
