"""Archimedes under resting blocks (issue #44): the fluid load on blocks that rest on the floor of
a closed tank of still water, with ``coupling.hidden_pressure: hydrostatic``.

The gap fill (fcm/levelset.py) hides the underside of a block on the floor, the lower parts of
its sides, and the faces between the blocks of a stack; the hidden-surface pressure
(fcm/hidden.py) extends the static pressure over them. The reference is Archimedes,
F = ρ g V upwards (per ``coupling.depth`` in 2D), V the volume of the bodies' union (a
clump's overlapping spheres counted once, a stack's inner faces not at all). Poses:

* ``flat``: a 0.10 × 0.04 (× 0.06) block lying on the floor;
* ``tilted``: the same block turned 20° about a horizontal axis, resting on one edge;
* ``stack``: two bonded 0.10 × 0.02 blocks, one on the other (the outer shape of ``flat``);
* ``clump``: two spheres of radius 2 cm, centres 2 cm apart, resting on the floor;
* ``free``: the ``flat`` block held in mid-water, 6 cm above the floor: nothing is hidden
  (reported: the static part of the load comes from the samples of the true surface, the
  flow's part from the cut surface Γ, so this is the closure's error without a gap);
* ``cad`` (3D): the ``flat`` block read from an STL file (``shape: mesh``, one rigid block, the
  fluid seeing its signed-distance grid);
* ``cad_grid`` (3D): the same file cut on a 2 cm grid into 30 bonded pieces (``fill:
  bonded_grid``): the faces between them are hidden, the lift is the outer volume's.

Every block is held still by a velocity control (the tilted one would topple), and the load
is read after four 1 ms steps. 2D: structured triangles of the cell size; 3D: a gmsh box of
2 cm cells refined to the cell size round the blocks. Each resting pose's lift within 1 % of
ρ g V (issue #44): quick 5 mm (2D) and 7 mm (3D), full 2.5 mm and 4 mm; the full level also
checks the horizontal load within 1 % of ρ g V.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ...config import case_from_dict
from ...config.mesh import box_boundary_names
from ...io.logging import get_logger
from ...io.timing import StageTimer
from ...simulation.coupled import CoupledModel
from ..registry import Metric, at_most, register, rel_error_metric, report_only

log = get_logger("verify")

RHO, G = 998.2, 9.81                      # water [kg/m³], gravity [m/s²]
TANK = (0.3, 0.2, 0.21)                   # x, y (3D), height [m]
BLOCK = (0.10, 0.04, 0.06)                # length, height, width (3D) / depth (2D) [m]
CENTRE = (0.1513, 0.1007)                 # block centre in x and (3D) y [m], off the mesh lines
TILT = 20.0                               # [deg]
SPHERE_R, SPHERE_GAP = 0.02, 0.02         # clump: radius and centre distance [m]
FREE_LIFT = 0.06                          # the free block's bottom above the floor [m]
STEPS, DT = 4, 1.0e-3
POSES = ("flat", "tilted", "stack", "clump", "free", "cad", "cad_grid")
LEVELS = {"quick": {2: (0.005, POSES[:4]), 3: (0.007, ("flat", "tilted", "free", "cad_grid"))},
          "full": {2: (0.0025, POSES[:4]), 3: (0.004, POSES)}}
CAD_GRID = 0.02                           # cad_grid: the cells' edge [m] (5 × 3 × 2 pieces)
TOL = 0.01                                # Archimedes (issue #44)


def union_volume(dim: int) -> float:
    """Volume [m³] (3D) or area × depth [m³] (2D) of the clump's two overlapping spheres
    (discs in 2D): two balls less their lens."""
    r, d = SPHERE_R, SPHERE_GAP
    if dim == 3:
        return 2 * 4 / 3 * np.pi * r ** 3 - np.pi * (4 * r + d) * (2 * r - d) ** 2 / 12
    lens = 2 * r * r * np.arccos(d / (2 * r)) - 0.5 * d * np.sqrt(4 * r * r - d * d)
    return (2 * np.pi * r * r - lens) * BLOCK[2]


def displaced_volume(dim: int, pose: str) -> float:
    """V of Archimedes for ``pose`` [m³] (2D: area × coupling.depth)."""
    return union_volume(dim) if pose == "clump" else BLOCK[0] * BLOCK[1] * BLOCK[2]


def _position(dim: int, x: float, height: float) -> list[float]:
    """A centre at ``x`` and ``height`` above the floor: (x, height, 0) in 2D, (x, y, height) in 3D."""
    return [float(x), float(height), 0.0] if dim == 2 else [float(x), float(CENTRE[1]), float(height)]


def _box(dim: int, x: float, height: float, thickness: float, angle: float = 0.0, bonded: bool = False) -> dict:
    size = [BLOCK[0], thickness, BLOCK[2]] if dim == 2 else [BLOCK[0], BLOCK[2], thickness]
    return {"shape": "box", "material": "stone", "position": _position(dim, x, height), "size": size,
            "radius": 0.004, "axis": [0, 0, 1] if dim == 2 else [0, 1, 0], "angle": angle, "bonded": bonded}


def blocks(dim: int, pose: str) -> list[dict]:
    """The DEM blocks of ``pose`` (module docstring)."""
    x, h = CENTRE[0], BLOCK[1]
    if pose == "flat":
        return [_box(dim, x, h / 2, h)]
    if pose == "free":
        return [_box(dim, x, FREE_LIFT + h / 2, h)]
    if pose == "tilted":
        a = np.radians(TILT)
        return [_box(dim, x, 0.5 * BLOCK[0] * np.sin(a) + 0.5 * h * np.cos(a), h, TILT)]
    if pose == "stack":
        return [_box(dim, x, h / 4, h / 2, bonded=True), _box(dim, x, 3 * h / 4, h / 2, bonded=True)]
    if pose in ("cad", "cad_grid"):          # the flat block from its file: origin at its centre
        cad = {"shape": "mesh", "material": "stone", "file": "block.stl", "position": _position(dim, x, h / 2),
               "radius": 0.004, "sdf_spacing": 0.004, "sdf_margin": 0.09}
        return [{**cad, "fill": "bonded_grid", "grid_size": CAD_GRID} if pose == "cad_grid" else cad]
    if pose == "clump":
        half = SPHERE_GAP / 2
        return [{"shape": "clump", "material": "stone", "position": _position(dim, x, SPHERE_R),
                 "spheres": [[-half, 0.0, 0.0, SPHERE_R], [half, 0.0, 0.0, SPHERE_R]]}]
    raise ValueError(f"unknown pose {pose!r}")


def still_water_case(dim: int, pose: str, cell: float, out: Path) -> dict:
    """Closed tank of still water (slip walls, p pinned at the top corner) with the blocks of
    ``pose`` held still on the floor; ``cell`` [m] the cell size at the blocks."""
    upper = [TANK[0], TANK[2]] if dim == 2 else list(TANK)
    if dim == 2:
        mesh = {"kind": "rectangle", "lower": [0.0, 0.0], "upper": upper,
                "cells": [int(round(TANK[0] / cell)), int(round(TANK[2] / cell))]}
    else:
        mesh = {"kind": "gmsh_box", "lower": [0.0, 0.0, 0.0], "upper": upper, "size": 0.02,
                "refine": [{"lower": [0.08, 0.06, 0.0], "upper": [0.22, 0.14, FREE_LIFT + 0.09], "size": cell}]}
    up = [0.0, 1.0, 0.0] if dim == 2 else [0.0, 0.0, 1.0]
    bl = blocks(dim, pose)
    data = {
        "name": f"buoyancy_{dim}d_{pose}",
        "run": {"t_end": STEPS * DT, "dt": DT, "cfl": None, "log_every": STEPS, "output_every": 1000,
                "checkpoint_every": 1000},
        "mesh": mesh,
        "fluid": {"density": RHO, "viscosity": 1.0e-3, "gravity": [-G * u for u in up[:dim]],
                  "pressure_reference": upper,
                  "boundaries": [{"boundary": b, "kind": "slip"} for b in box_boundary_names(dim)]},
        "dem": {"dt": 1.0e-5, "gravity": [-G * u for u in up],
                "materials": [{"name": "stone", "stiffness": 1.0e6, "restitution": 0.2, "friction_angle": 30.0,
                               "density": 2400.0}],
                "blocks": bl,
                "controls": [{"block": i, "modes": ["velocity"] * 6, "values": [0.0] * 6} for i in range(len(bl))],
                "walls": [{"kind": "plane", "material": "stone", "point": [0.0, 0.0, 0.0], "normal": up}]},
        "coupling": {"hidden_pressure": "hydrostatic", **({"depth": BLOCK[2]} if dim == 2 else {})},
        "output": {"directory": str(out), "xdmf": False},
    }
    if pose in ("cad", "cad_grid"):
        for b in data["dem"]["blocks"]:
            b["file"] = str(_block_file(out))
        data["dem"]["controls"] = [{"block": i, "modes": ["velocity"] * 6, "values": [0.0] * 6}
                                   for i in range(30 if pose == "cad_grid" else 1)]
    if pose in ("stack", "cad_grid"):
        data["dem"]["cohesive"] = {"sigma_c": 2.0e4, "delta_f": 1.0e-3, "mode": "reversible", "points_per_edge": 2}
    if pose == "free":
        data["dem"]["blocks"][0]["fixed"] = True
        data["dem"]["controls"] = []
    return data


def _block_file(out: Path) -> Path:
    """The ``flat`` block (3D) as a 12-triangle STL centred on its file origin, written once by
    rank 0 into ``out``."""
    path = Path(out) / "block.stl"
    comm = MPI.COMM_WORLD
    if comm.rank == 0 and not path.exists():
        import meshio
        half = 0.5 * np.array([BLOCK[0], BLOCK[2], BLOCK[1]])
        corner = np.array([[k & 1, (k >> 1) & 1, (k >> 2) & 1] for k in range(8)], float)
        quads = ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5))
        tri = [(q[0], q[1], q[2]) for q in quads] + [(q[0], q[2], q[3]) for q in quads]
        path.parent.mkdir(parents=True, exist_ok=True)
        meshio.write(str(path), meshio.Mesh(-half + 2 * half * corner, [("triangle", np.array(tri))]))
    comm.Barrier()
    return path


def resting_load(data: dict, comm: MPI.Comm) -> tuple[np.ndarray, int]:
    """Total fluid load (3,) [N] on all blocks after the steps, and the global cell count."""
    model = CoupledModel(case_from_dict(data), comm)
    t, timer = 0.0, StageTimer()
    for _ in range(STEPS):
        model.advance(t, DT, timer)
        t += DT
    cells = model.mesh.topology.index_map(model.mesh.topology.dim).size_global
    return model.exchange.force.sum(axis=0), cells


def _vertical(dim: int, force: np.ndarray) -> tuple[float, float]:
    return float(force[dim - 1]), float(np.linalg.norm(force[: dim - 1]))


@register("buoyancy", "blocks resting on the floor of still water (flat, tilted on an edge, a bonded stack, a "
          "sphere clump) get Archimedes' lift ρgV through the hidden-surface pressure, 2D and 3D", issue=44)
def buoyancy(level: str, out: Path, comm: MPI.Comm) -> list[Metric]:
    metrics, table = [], {}
    for dim, (cell, poses) in LEVELS[level].items():
        errors = table[dim] = {}
        for pose in poses:
            t0 = time.perf_counter()
            force, cells = resting_load(still_water_case(dim, pose, cell, out / f"{dim}d_{pose}"), comm)
            weight = RHO * G * displaced_volume(dim, pose)
            up, side = _vertical(dim, force)
            errors[pose] = up / weight - 1.0
            log.info("buoyancy %dD %s at %.4g m: F_up %.6g N, ρgV %.6g N (%+.3f %%), |F_side| %.3g N, %d cells, %.1f s",
                     dim, pose, cell, up, weight, 100 * errors[pose], side, cells, time.perf_counter() - t0)
            tag = f"{dim}d_{pose}"
            if pose == "free":
                metrics.append(report_only(f"lift_rel_error_{tag}", errors[pose], reference=0.0,
                                           note=f"the cut geometry's own error at {cell * 1e3:g} mm cells"))
            else:
                metrics.append(rel_error_metric(f"lift_{tag}", up, weight, TOL, unit="N"))
            if level == "full":
                metrics.append(at_most(f"side_force_{tag}", side / weight, TOL))
            else:
                metrics.append(report_only(f"side_force_{tag}", side / weight, reference=0.0))
            metrics.append(report_only(f"cells_{dim}d_{pose}", float(cells)))
    if comm.rank == 0:
        _plot(out, table, level)
    return metrics


def _plot(out: Path, table: dict, level: str) -> None:
    """Relative lift error per pose, 2D and 3D, against the ±1 % band."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    for k, (dim, errors) in enumerate(sorted(table.items())):
        cell = LEVELS[level][dim][0]
        x = [POSES.index(p) + 0.15 * (2 * k - 1) for p in errors]
        ax.bar(x, [100 * e for e in errors.values()], width=0.3, label=f"{dim}D, {cell * 1e3:g} mm cells")
    ax.axhspan(-100 * TOL, 100 * TOL, color="0.85", zorder=0, label="±1 %")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(range(len(POSES)), [p if p != "free" else "free (not resting)" for p in POSES])
    ax.set_ylabel("(F_up − ρgV) / ρgV [%]")
    ax.set_title(f"buoyancy of resting bodies in still water ({level} level)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "buoyancy.png", dpi=110)
    plt.close(fig)
