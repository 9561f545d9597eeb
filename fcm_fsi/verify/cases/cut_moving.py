"""Bodies with prescribed motion, and at rest under gravity, in the finite-cover cut (issue #5).

moving_cylinder  (2D) Galilean check: a cylinder towed at −U through fluid at rest against the
                 same cylinder held in a uniform stream U, on the same fixed unstructured mesh.
                 With slip side walls, an inflow boundary upstream and do-nothing downstream,
                 the two problems are one and the same in the cylinder's frame, so their drag
                 histories must agree: the towed one crosses the mesh (new cut every step,
                 nodes leaving and entering the body), the fixed one does not. The metric is
                 the relative difference of the mean c_D over t U/D ∈ [4, 8] (≤ 2 %).
                 The in-line oscillating cylinder of Dütsch et al. (1998; Re 100, KC 5)
                 is run on the same machinery when reference profiles are available.
submerged_box    a rotated box held fixed in a closed tank of still water (2D and 3D at the
                 full level): vertical force on the box = ρ g V (≤ 0.5 %), max |u| after 1 s
                 (≤ 1e-4 m/s).
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ...config.fluid import BoundaryCondition, FluidConfig, StabilizationConfig
from ...config.mesh import MeshConfig, RefineZone
from ...fcm.levelset import Shapes, StructureLevelSet
from ...fluid.cut_walls import CutDomain
from ...fluid.navier_stokes import NavierStokes
from ...io.logging import get_logger
from ...mesh.build import gmsh_box
from ...mesh.channel import tag_box_boundaries
from ..registry import Metric, at_most, register, rel_error_metric, report_only

log = get_logger("verify.cut_moving")

IDENTITY = np.array([[1.0, 0.0, 0.0, 0.0]])


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


# ------------------------------------------------------------------ moving_cylinder
@dataclasses.dataclass(frozen=True)
class TowSetup:
    """Dimensionless set-up (D = U = ρ = 1, ν = 1/Re) of the Galilean check."""

    re: float = 20.0
    length: float = 24.0           # channel [0, length] × [−half_height, half_height]
    half_height: float = 6.0
    x_fixed: float = 10.0          # the fixed cylinder's centre
    x_tow_start: float = 14.0      # the towed cylinder starts here and moves at −U
    t_end: float = 8.0
    window: tuple[float, float] = (4.0, 8.0)   # c_D mean over this time window
    h_near: float = 0.1            # cell size in the band the cylinders sweep
    h_far: float = 0.3             # (gmsh drops a 3-wide refine zone when the outside size is ≥ 0.8)
    dt: float = 0.05


def _tow_mesh(comm, s: TowSetup):
    cfg = MeshConfig(kind="gmsh_box", lower=(0.0, -s.half_height), upper=(s.length, s.half_height),
                     size=s.h_far, refine=(RefineZone(lower=(s.x_fixed - 5.0, -1.5), upper=(s.x_tow_start + 5.0, 1.5),
                                                      size=s.h_near),))
    msh = gmsh_box(cfg, comm)
    from ...mesh.build import min_cell_size
    if min_cell_size(msh) > 2.0 * s.h_near:
        raise RuntimeError(f"moving_cylinder mesh: smallest cell {min_cell_size(msh):.3g} > 2 h_near = "
                           f"{2 * s.h_near:g}: gmsh did not apply the refine zone (h_far {s.h_far:g})")
    return tag_box_boundaries(msh, (0.0, -s.half_height), (s.length, s.half_height))


def cylinder_run(comm, s: TowSetup, towed: bool, tm=None) -> dict:
    """c_D(t) of the fixed (uniform stream +U) or towed (velocity −U, fluid at rest) cylinder."""
    tm = tm or _tow_mesh(comm, s)
    msh = tm.mesh
    cut = CutDomain(msh)
    cutoff = 0.5
    ls = StructureLevelSet(Shapes.cylinder((0.0, 0.0, 0.0), 0.5, 1.0 + 4 * cutoff, body=0), nbodies=1,
                           cutoff=cutoff)
    inflow = 0.0 if towed else 1.0
    bcs = (BoundaryCondition(boundary="xmin", kind="velocity", value=(inflow, 0.0)),
           BoundaryCondition(boundary="ymin", kind="slip"), BoundaryCondition(boundary="ymax", kind="slip"),
           BoundaryCondition(boundary="xmax", kind="do_nothing"))
    cfg = FluidConfig(density=1.0, viscosity=1.0 / s.re, boundaries=bcs, theta=0.5, rtol=1e-8, atol=1e-12,
                      quadrature_degree=cut.degree, stabilization=StabilizationConfig())
    wall_u = np.array([-1.0, 0.0]) if towed else np.zeros(2)

    def place(t: float):
        x = s.x_tow_start - t if towed else s.x_fixed
        centre = np.array([[x, 0.0, 0.0]])
        level, owner = ls.evaluate(cut.nodes, centre, IDENTITY)
        ubar = np.where((owner >= 0)[:, None], wall_u[None, :], 0.0)
        cut.update(level, owner, ubar)
        return centre

    place(0.0)
    ns = NavierStokes(msh, cfg, s.dt, facet_tags=tm.facet_tags, boundary_names=tm.names, dx=cut.dx,
                      extra_terms=[cut.penalty_term()])
    ns.set_velocity(lambda x: np.vstack([np.full(x.shape[1], inflow), 0 * x[0]]))
    times, cd, cl = [], [], []
    nsteps = int(round(s.t_end / s.dt))
    for n in range(nsteps):
        t_new = (n + 1) * s.dt
        centre = place(t_new - 0.5 * s.dt)        # the wall at the CN mid-point t^{n+1/2}
        ns.step()
        force, _ = cut.body_forces(1, centre[:, :2])
        times.append(t_new)
        cd.append(2.0 * force[0, 0])              # c_D = F/(½ ρ U² D), ρ = U = D = 1
        cl.append(2.0 * force[0, 1])
    t, cd = np.array(times), np.array(cd)
    w = (t >= s.window[0]) & (t <= s.window[1])
    return {"t": t, "c_D": cd, "c_L": np.array(cl), "mean_c_D": float(cd[w].mean()),
            "cells": int(msh.topology.index_map(2).size_global)}


@register("moving_cylinder", "cylinder towed through fluid at rest vs fixed in a uniform stream "
          "(Galilean check, finite-cover cut on a fixed mesh)", issue=5)
def moving_cylinder(level, out_dir: Path, comm) -> list[Metric]:
    s = TowSetup(h_near=0.1, dt=0.025) if level == "full" else TowSetup(h_near=0.2, dt=0.1)
    t0 = time.perf_counter()
    tm = _tow_mesh(comm, s)
    fixed = cylinder_run(comm, s, towed=False, tm=tm)
    towed = cylinder_run(comm, s, towed=True, tm=tm)
    wall = time.perf_counter() - t0
    diff = abs(towed["mean_c_D"] - fixed["mean_c_D"]) / fixed["mean_c_D"]
    log.info("moving_cylinder: mean c_D fixed %.5f towed %.5f (diff %.3e), %d cells, %.1f s",
             fixed["mean_c_D"], towed["mean_c_D"], diff, fixed["cells"], wall)
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(fixed["t"], fixed["c_D"], label="fixed cylinder, uniform stream U")
        ax.plot(towed["t"], towed["c_D"], "--", label="towed at −U through fluid at rest")
        ax.axvspan(*s.window, color="0.9", zorder=0, label="averaging window")
        ax.set_xlabel("t U / D")
        ax.set_ylabel("c_D")
        ax.set_ylim(0, max(4.0, 1.2 * fixed["mean_c_D"]))
        ax.set_title(f"Galilean check, Re {s.re:g}, h = D/{1 / s.h_near:g}: mean c_D "
                     f"{fixed['mean_c_D']:.4f} vs {towed['mean_c_D']:.4f} ({100 * diff:.2f} %)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out_dir / "moving_cylinder_galilean.png", dpi=120)
        plt.close(fig)
    return [at_most("galilean_c_D_diff", diff, 0.02),
            report_only("c_D_fixed", fixed["mean_c_D"], note=f"Re {s.re:g}, h = D/{1 / s.h_near:g}, blockage 1/12"),
            report_only("c_D_towed", towed["mean_c_D"]),
            report_only("cells", float(fixed["cells"])),
            report_only("wall_seconds", wall, unit="s")]


# --------------------------------------------------------------------- submerged_box
#: half extents of the rotated box's bounding box (3D), for the refine zone around it
BOX_HALF_EXTENT = (0.1666, 0.1218, 0.1)


def submerged_box_run(comm, dim: int, n: int, t_end: float = 1.0, dt: float = 0.05,
                      refine: float | None = None) -> dict:
    """Box 0.3 × 0.15 (× 0.2) rotated 20° about z, centred in a closed unit tank full of water
    at rest (ρ 1000, μ 1e-3, g 9.81), held fixed: vertical force and max |u| after ``t_end``.
    ``refine`` (3D): a gmsh mesh, cells 1/n outside and ``refine`` in a zone 3 cells wider than
    the box's bounding box, instead of the structured n³ box."""
    from scipy.spatial.transform import Rotation

    from ...mesh.channel import box, rectangle
    rho, g = 1000.0, 9.81
    if dim == 2:
        tm = rectangle(comm, n=(n, n))
    elif refine is not None:
        half = np.array(BOX_HALF_EXTENT) + 3 * refine
        cfg = MeshConfig(kind="gmsh_box", lower=(0.0, 0.0, 0.0), upper=(1.0, 1.0, 1.0), size=1.0 / n,
                         refine=(RefineZone(lower=tuple(0.5 - half), upper=tuple(0.5 + half), size=refine),))
        tm = tag_box_boundaries(gmsh_box(cfg, comm), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    else:
        tm = box(comm, n=(n, n, n))
    msh = tm.mesh
    cut = CutDomain(msh)
    size = (0.3, 0.15, 0.2 if dim == 3 else 1.0 + 0.4)
    rot = Rotation.from_euler("z", 20.0, degrees=True).as_matrix()
    ls = StructureLevelSet(Shapes.box((0.0, 0.0, 0.0), size, rot=rot, body=0), nbodies=1, cutoff=0.1)
    centre = np.array([[0.5, 0.5, 0.5 if dim == 3 else 0.0]])
    level, owner = ls.evaluate(cut.nodes, centre, IDENTITY)
    stats = cut.update(level, owner, np.zeros((len(level), dim)))
    walls = tuple(tm.names)          # every side of the box
    gravity = (0.0, -g) if dim == 2 else (0.0, -g, 0.0)
    cfg = FluidConfig(density=rho, viscosity=1e-3, gravity=gravity, rtol=1e-10, atol=1e-10,
                      quadrature_degree=cut.degree, pressure_reference=(0.0, 1.0) if dim == 2 else (0.0, 1.0, 0.0),
                      boundaries=tuple(BoundaryCondition(boundary=b, kind="no_slip") for b in walls))
    ns = NavierStokes(msh, cfg, dt, facet_tags=tm.facet_tags, boundary_names=tm.names, dx=cut.dx,
                      extra_terms=[cut.penalty_term()])
    for _ in range(int(round(t_end / dt))):
        ns.step()
    force, _ = cut.body_forces(1, centre[:, :dim])
    # max |u| over the velocity nodes in the fluid (the fictitious flow inside is not reported)
    u = ns.U.x.array[ns.V_map].reshape(-1, dim)
    level_v = np.empty(len(u))
    level_v[cut.node_map(ns.V)] = level
    u = u[level_v > 0]
    umax = comm.allreduce(float(np.sqrt((u ** 2).sum(axis=1)).max(initial=0.0)), op=MPI.MAX)
    volume_exact = size[0] * size[1] * (size[2] if dim == 3 else 1.0)
    volume_cut = 1.0 - stats.fluid_volume          # unit tank
    return {"F_up": float(force[0, 1]), "rho_g_V": rho * g * volume_exact, "rho_g_V_cut": rho * g * volume_cut,
            "umax": umax, "cells": int(msh.topology.index_map(dim).size_global)}


@register("submerged_box", "rotated box held fixed in still water: buoyancy ρgV and spurious velocity "
          "(finite-cover cut, 2D; full level also 3D)", issue=5)
def submerged_box(level, out_dir: Path, comm) -> list[Metric]:
    # (dim, n, refine): the 3D gmsh run refines a zone around the box to `refine` (cells 1/n outside)
    runs = ([(2, 80, None)] if level == "quick" else
            [(2, 40, None), (2, 80, None), (2, 160, None), (2, 320, None), (3, 24, None), (3, 36, None),
             (3, 24, 0.008), (3, 24, 0.006)])
    metrics, rows = [], []
    for dim, n, refine in runs:
        t0 = time.perf_counter()
        r = submerged_box_run(comm, dim, n, refine=refine)
        r["wall"] = time.perf_counter() - t0
        rows.append((dim, n, refine, r))
        log.info("submerged_box %dD n %d refine %s: F_up %.6g, ρgV %.6g (cut volume %.6g), max|u| %.3e, %d cells, "
                 "%.1f s", dim, n, refine, r["F_up"], r["rho_g_V"], r["rho_g_V_cut"], r["umax"], r["cells"], r["wall"])
    last = {d: i for i, (d, _, _, _) in enumerate(rows)}      # the finest (last) run of each dimension
    for i, (dim, n, refine, r) in enumerate(rows):
        tag = "" if i == last.get(2) else f"_{dim}d_n{n}" + (f"_h{refine:g}" if refine else "")
        # the target applies to the finest mesh of each dimension; coarser rows show the convergence
        # of the cut volume (the P1 level set rounds the box's corners and, in 3D, its edges)
        buoyancy = (rel_error_metric("buoyancy_rel_error" + tag, r["F_up"], r["rho_g_V"], 0.005)
                    if i == last[dim] else
                    report_only("buoyancy_rel_error" + tag, r["F_up"] / r["rho_g_V"] - 1, reference=0.0,
                                note="coarser mesh: convergence, no target"))
        mesh_note = (f"{dim}D structured, n = {n}" if refine is None else
                     f"3D gmsh, {1 / n:.3g} m outside, {refine:g} m around the box")
        metrics += [buoyancy,
                    at_most("spurious_velocity" + tag, r["umax"], 1e-4, unit="m/s"),
                    report_only("buoyancy_vs_cut_volume" + tag, r["F_up"] / r["rho_g_V_cut"] - 1,
                                note="against ρ g times the discrete (piecewise-planar) cut volume"),
                    report_only("cells" + tag, float(r["cells"]), note=mesh_note)]
    if comm.rank == 0 and len(rows) > 1:
        plt = _plt()
        fig, ax = plt.subplots(figsize=(6, 4))
        two = [(n, r) for d, n, _, r in rows if d == 2]
        ax.loglog([1 / n for n, _ in two], [abs(r["F_up"] / r["rho_g_V"] - 1) for _, r in two], "o-",
                  label="|F_up / ρgV − 1| (2D)")
        ax.axhline(0.005, color="k", ls=":", label="target 0.5 %")
        ax.set_xlabel("h [m]")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out_dir / "submerged_box_buoyancy.png", dpi=120)
        plt.close(fig)
    return metrics
