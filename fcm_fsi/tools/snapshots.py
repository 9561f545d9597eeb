"""Rendered snapshots of a 3D coupled run without ParaView (matplotlib): the free surface
φ = ½ of the phase field (marching tetrahedra on the P1 field of ``fields*.h5``) and the
blocks' spheres of ``blocks.pvd`` coloured by damage (fraction of the block's bonds broken)
and, in grey, the blocks as the fluid sees them (the structure level set's zero surface),
seen from upstream (front, −x) and from downstream (back, +x) — the views of the paper's
Fig. 18–19. Needs a run with field output on (``output.xdmf: true``)::

    python -m fcm_fsi snapshots OUTPUT_DIR --times 5 9            # → OUTPUT_DIR/snapshot_t5_front.png, …

Each requested time is drawn at the nearest stored output time (both are in the title).
"""
from __future__ import annotations

import argparse
import base64
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..io.vtp import read_pvd

#: the phase-field value drawn as the free surface
SURFACE = 0.5
#: (elevation, azimuth) [deg] of the two views; the water comes from −x
VIEWS = {"front": (20.0, -150.0), "back": (20.0, 30.0)}


# ------------------------------------------------------------------ geometry
def isosurface(points: np.ndarray, tets: np.ndarray, values: np.ndarray, level: float) -> np.ndarray:
    """Triangles (m, 3, 3) [m] of the surface ``values`` = ``level`` of a P1 field on
    tetrahedra (marching tetrahedra: one triangle where one vertex is on the other side, two
    where two are; the crossing points linearly interpolated along the edges)."""
    v = values[tets] - level                        # (n, 4)
    above = v > 0
    count = above.sum(axis=1)
    tris = []
    for k in (1, 3):                                # one vertex apart: a triangle
        sel = np.flatnonzero(count == k)
        if not sel.size:
            continue
        lone = np.argmax(above[sel] if k == 1 else ~above[sel], axis=1)
        others = np.array([[j for j in range(4) if j != i] for i in range(4)])[lone]
        tris.append(np.stack([_cross(points, tets[sel], v[sel], lone, others[:, j]) for j in range(3)], axis=1))
    sel = np.flatnonzero(count == 2)                # two and two: a quadrilateral, two triangles
    if sel.size:
        order = np.argsort(~above[sel], axis=1, kind="stable")    # the two above first
        a0, a1, b0, b1 = order.T
        quad = [_cross(points, tets[sel], v[sel], a, b) for a, b in ((a0, b0), (a0, b1), (a1, b1), (a1, b0))]
        tris.append(np.stack([quad[0], quad[1], quad[2]], axis=1))
        tris.append(np.stack([quad[0], quad[2], quad[3]], axis=1))
    return np.concatenate(tris) if tris else np.zeros((0, 3, 3))


def _cross(points, tets, v, i, j) -> np.ndarray:
    """Where the field crosses zero on the edge (i, j) of each tetrahedron."""
    rows = np.arange(len(tets))
    vi, vj = v[rows, i], v[rows, j]
    s = (vi / (vi - vj))[:, None]
    return points[tets[rows, i]] * (1 - s) + points[tets[rows, j]] * s


# ------------------------------------------------------------------ reading
def field_times(out_dir: Path, name: str = "phi") -> list[tuple[float, Path, str]]:
    """(time [s], h5 file, dataset) of every stored output of field ``name`` in the
    ``fields*.h5`` of a run folder (a restart writes ``fields_from_stepN.h5``), by time."""
    import h5py
    found = []
    for h5 in sorted(Path(out_dir).glob("fields*.h5")):
        with h5py.File(h5, "r") as f:
            if f"Function/{name}" not in f:
                continue
            for key in f[f"Function/{name}"]:
                found.append((float(key.replace("_", ".")), h5, f"Function/{name}/{key}"))
    return sorted(found, key=lambda e: e[0])


def read_field(h5: Path, dataset: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (n, 3), cells (m, k), values (n,)) of a P1 field written by dolfinx's XDMFFile."""
    import h5py
    with h5py.File(h5, "r") as f:
        x = f["Mesh/mesh/geometry"][...]
        cells = f["Mesh/mesh/topology"][...]
        values = f[dataset][...].reshape(len(x), -1)[:, 0]
    if x.shape[1] == 2:
        x = np.column_stack([x, np.zeros(len(x))])
    return x, cells.astype(np.int64), values


def _has(h5: Path, dataset: str) -> bool:
    import h5py
    with h5py.File(h5, "r") as f:
        return dataset in f


def read_vtp(path: Path) -> dict[str, np.ndarray]:
    """Point coordinates (``Points``) and point data of a PolyData file written by
    :func:`fcm_fsi.dem.output.write_vtp` (binary, UInt32 header)."""
    types = {"Float64": np.float64, "Float32": np.float32, "Int64": np.int64}
    out = {}
    for arr in ET.parse(path).getroot().iter("DataArray"):
        raw = base64.b64decode(arr.text.strip())
        a = np.frombuffer(raw[4:], dtype=types[arr.get("type")])
        ncomp = int(arr.get("NumberOfComponents", "1"))
        out[arr.get("Name")] = a.reshape(-1, ncomp) if ncomp > 1 else a
    return out


# ------------------------------------------------------------------ drawing
def render(out_dir: Path, time: float, png_dir: Path | None = None, views=VIEWS) -> list[Path]:
    """PNG per view of the state nearest ``time`` [s]; returns the files written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    out_dir = Path(out_dir)
    png_dir = Path(png_dir) if png_dir is not None else out_dir
    png_dir.mkdir(parents=True, exist_ok=True)
    stored = field_times(out_dir)
    if not stored:
        raise FileNotFoundError(f"{out_dir}: no fields*.h5 with a phase field 'phi' (run with output.xdmf: true)")
    t_f, h5, ds = min(stored, key=lambda e: abs(e[0] - time))
    x, cells, phi = read_field(h5, ds)
    if cells.shape[1] != 4:
        raise ValueError(f"{h5}: snapshots draw 3D (tetrahedral) runs; this mesh has {cells.shape[1]}-node cells")
    surface = isosurface(x, cells, phi, SURFACE)
    solid = np.zeros((0, 3, 3))
    level_ds = ds.replace("Function/phi/", "Function/structure_level_set/")
    if _has(h5, level_ds):          # the blocks as the fluid sees them (widened), in grey
        solid = isosurface(x, cells, read_field(h5, level_ds)[2], 0.0)
    blocks = read_pvd(out_dir / "blocks.pvd")
    spheres, t_b = None, None
    if blocks:
        t_b, name = min(blocks, key=lambda e: abs(e[0] - time))
        spheres = read_vtp(out_dir / name)
    lo, hi = x.min(axis=0), x.max(axis=0)
    written = []
    for view, (elev, azim) in views.items():
        fig = plt.figure(figsize=(9, 6))
        ax = fig.add_subplot(projection="3d")
        if len(solid):
            ax.add_collection3d(Poly3DCollection(solid, facecolor=(0.55, 0.55, 0.55, 0.5), edgecolor="none"))
        if len(surface):
            ax.add_collection3d(Poly3DCollection(surface, facecolor=(0.25, 0.5, 0.9, 0.35), edgecolor="none"))
        if spheres is not None:
            p = spheres["Points"]
            sc = ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=spheres.get("damage", np.zeros(len(p))), cmap="inferno_r",
                            vmin=0.0, vmax=1.0, s=6, depthshade=False)
            fig.colorbar(sc, ax=ax, shrink=0.6, label="block damage (fraction of bonds broken)")
        ax.set_xlim(lo[0], hi[0]), ax.set_ylim(lo[1], hi[1]), ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.view_init(elev=elev, azim=azim)
        ax.set_xlabel("x [m]"), ax.set_ylabel("y [m]"), ax.set_zlabel("z [m]")
        blk = f", blocks at t = {t_b:.3g} s" if t_b is not None else ", no blocks.pvd"
        ax.set_title(f"{view}: free surface φ = ½ at t = {t_f:.3g} s{blk} (asked {time:g} s)")
        path = png_dir / f"snapshot_t{time:g}_{view}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("output", type=Path, help="output folder of a 3D coupled run with field output")
    ap.add_argument("--times", type=float, nargs="+", required=True, help="times [s] to draw")
    ap.add_argument("--png-dir", type=Path, default=None, help="where to write the PNGs (default: the output folder)")


def run(args: argparse.Namespace) -> int:
    try:
        for t in args.times:
            for path in render(args.output, t, args.png_dir):
                print(path)
    except (FileNotFoundError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0
