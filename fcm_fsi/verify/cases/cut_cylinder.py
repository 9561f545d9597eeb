"""Schäfer–Turek cylinder benchmarks on UNFITTED meshes: the finite-cover cut (issue #5).

The channel is meshed without the cylinder hole (``mesh.channel.channel_unfitted``); the
cylinder is a level set of the structure (``fcm.levelset``: a capped ``Shapes.cylinder``
carried by body 0 at rest) and is cut out by ``fluid.cut_walls.CutDomain``: moment-fitted
quadrature on the fluid part of cut cells, fictitious factor α on the solid part, the
default (``pressure``) wall terms with p̄ = γ(μ/h + ρh/Δt) on Γ. Drag and lift are the wall
traction on Γ
(``CutDomain.body_forces``), Δp the P1 pressure at the front and back points of the
cylinder (points on Γ, inside cut cells).

cylinder_2d1_cut:  2D-1 (Re 20), targets of issue #5: c_D ± 2 %, Δp ± 3 %.
cylinder_3d1z_cut: 3D-1Z (Re 20, square channel), targets c_D ± 3 %, Δp ± 3 %.

γ = 100 and α = 1e-3 are fixed here (the CutDomain defaults); docs/cut-domain.md has the
sensitivity to both.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from ...config.fluid import BoundaryCondition
from ...fcm.levelset import Shapes, StructureLevelSet
from ...fluid.cut_walls import CutDomain
from ...fluid.forces import probe
from ...fluid.navier_stokes import NavierStokes
from ...fluid.steady import march_to_steady
from ...io.logging import get_logger
from ...mesh import channel
from ..registry import Metric, error_order, register, rel_error_metric, report_only
from .navier_stokes import ST_2D1, ST_3D1Z, channel_config, cylinder_2d1_solution, plot_cylinder_convergence

log = get_logger("verify.cut_cylinder")

GAMMA, ALPHA = 100.0, 1e-3
RADIUS, U_MEAN, HEIGHT = 0.05, 0.2, 0.41


def cylinder_level_set(nodes: np.ndarray, dim: int, cutoff: float):
    """Level set φ (> 0 fluid) and owner body (0 near the cylinder) at the mesh nodes.

    2D: a z-cylinder of radius 0.05 at (0.2, 0.2), length 4·cutoff + 1 (the 2D points sit at
    z = 0; the extent along z must be ≥ 2·cutoff). 3D: the z-cylinder at (0.5, 0.2) through
    the whole channel height, its caps 2·cutoff beyond the walls."""
    if dim == 2:
        centre, length = (0.2, 0.2, 0.0), 1.0 + 4 * cutoff
    else:
        centre, length = (0.5, 0.2, 0.5 * HEIGHT), HEIGHT + 4 * cutoff
    shapes = Shapes.cylinder((0.0, 0.0, 0.0), RADIUS, length, body=0)
    ls = StructureLevelSet(shapes, nbodies=1, cutoff=cutoff)
    phi, owner = ls.evaluate(nodes, np.array([centre]), np.array([[1.0, 0.0, 0.0, 0.0]]))
    return phi, owner, np.array(centre[:dim])


def cut_cylinder_solution(comm, dim: int, h_cyl: float, h_far: float, gamma: float = GAMMA,
                          alpha: float = ALPHA, petsc: dict | None = None, wall: str | None = None,
                          band: tuple[float, float] | None = None) -> dict:
    """Steady Re-20 flow past the cut cylinder on ``channel_unfitted(comm, dim, h_cyl, h_far, band)``.

    ``wall``: the CutDomain wall term (None: its default). Returns a dict with c_D, c_L, dp,
    cells (global), cut_cells, min_cut_fraction, area_error (relative error of the fitted
    fluid measure against the exact one) and steps (pseudo-time steps)."""
    tm = channel.channel_unfitted(comm, dim, h_cyl, h_far, band=band)
    msh = tm.mesh
    cut = CutDomain(msh, alpha=alpha, penalty=gamma, **({} if wall is None else {"wall": wall}))
    cutoff = max(0.025, 4 * h_cyl)
    phi, owner, centre = cylinder_level_set(cut.nodes, dim, cutoff)
    stats = cut.update(phi, owner, np.zeros((len(phi), dim)))
    # the clip must not reach a cut cell, or its P1 level set would misplace Γ
    vals = phi[cut.geom_cells]
    in_cut = (vals.min(axis=1) < 0) & (vals.max(axis=1) >= 0)
    if np.any(np.abs(vals[in_cut]) >= cutoff):
        raise RuntimeError(f"level-set cutoff {cutoff} reached in a cut cell (h_cyl {h_cyl})")
    um = 0.3 if dim == 2 else 0.45
    bcs = (BoundaryCondition(boundary="inlet", kind="parabolic_inflow", max_speed=um),
           BoundaryCondition(boundary="walls", kind="no_slip"),
           BoundaryCondition(boundary="outlet", kind="do_nothing"))
    cfg = dataclasses.replace(channel_config(um, 1.0, False, petsc), boundaries=bcs,
                              quadrature_degree=cut.degree)
    if dim == 3:
        cfg = dataclasses.replace(cfg, rtol=1e-7)
    ns = NavierStokes(msh, cfg, 1.0 if dim == 2 else 0.5, facet_tags=tm.facet_tags,
                      boundary_names=tm.names, dx=cut.dx, extra_terms=[cut.penalty_term()])
    if dim == 2:
        steps = march_to_steady(ns, tol=1e-8, max_steps=100, growth=2.0, dt_max=1e4)
    else:
        steps = march_to_steady(ns, tol=1e-6, max_steps=60, growth=2.0, dt_max=1e3)
    force, _ = cut.body_forces(1, centre[None])
    scale = 2.0 / (1.0 * U_MEAN ** 2 * 2 * RADIUS * (1.0 if dim == 2 else HEIGHT))
    c_d, c_l = scale * force[0, 0], scale * force[0, 1]
    if dim == 2:
        pts = np.array([[0.15, 0.2, 0.0], [0.25, 0.2, 0.0]])
        exact = 2.2 * HEIGHT - np.pi * RADIUS ** 2
    else:
        pts = np.array([[0.45, 0.2, 0.205], [0.55, 0.2, 0.205]])
        exact = (2.5 * HEIGHT - np.pi * RADIUS ** 2) * HEIGHT
    p = probe(ns.p, pts)
    return {"c_D": float(c_d), "c_L": float(c_l), "dp": float(p[0] - p[1]),
            "cells": int(msh.topology.index_map(dim).size_global), "cut_cells": stats.cut_cells,
            "min_cut_fraction": stats.min_cut_fraction,
            "area_error": abs(stats.fluid_volume - exact) / exact, "steps": steps}


def _row(h_cyl: float, r: dict, wall: float) -> tuple:
    """A row of ``plot_cylinder_convergence``: (h, c_D, c_L, Δp, cells, wall)."""
    return (h_cyl, r["c_D"], r["c_L"], r["dp"], r["cells"], wall)


# ------------------------------------------------------------------------ 2D-1
@register("cylinder_2d1_cut", "Schäfer–Turek 2D-1 on an unfitted mesh (finite-cover cut, pressure wall): "
          "drag, pressure drop", issue=5)
def cylinder_2d1_cut(level, out_dir: Path, comm) -> list[Metric]:
    levels = [(0.005, 0.02)] if level == "quick" else [(0.01, 0.04), (0.005, 0.02), (0.0025, 0.01)]
    rows, fitted, last = [], [], None
    for h_cyl, h_far in levels:
        t0 = time.perf_counter()
        last = cut_cylinder_solution(comm, 2, h_cyl, h_far)
        rows.append(_row(h_cyl, last, time.perf_counter() - t0))
        log.info("2D-1 cut h_cyl %g: c_D %.6f c_L %.6f dp %.6f cells %d (%.1f s)", *rows[-1])
        if level == "full":          # the body-fitted mesh of the same size, for comparison
            t0 = time.perf_counter()
            fitted.append((h_cyl,) + cylinder_2d1_solution(comm, h_cyl, h_far) + (time.perf_counter() - t0,))
            log.info("2D-1 fitted h_cyl %g: c_D %.6f c_L %.6f dp %.6f cells %d (%.1f s)", *fitted[-1])
    if comm.rank == 0:
        for r in rows:
            print(f"  cut    h_cyl {r[0]:<7g} cells {r[4]:>6d}  c_D {r[1]:.5f}  c_L {r[2]:.5f}  dp {r[3]:.5f}  {r[5]:.1f} s")
        for r in fitted:
            print(f"  fitted h_cyl {r[0]:<7g} cells {r[4]:>6d}  c_D {r[1]:.5f}  c_L {r[2]:.5f}  dp {r[3]:.5f}  {r[5]:.1f} s")
        plot_cylinder_convergence(rows, ST_2D1, ("c_D", "c_L", "dp"), out_dir / "cylinder_2d1_cut_convergence.png",
                                  label="cut (wall traction)",
                                  compare={"body-fitted (reaction)": fitted} if fitted else None)
    h_cyl = levels[-1][0]
    metrics = [rel_error_metric("c_D", last["c_D"], ST_2D1["c_D"], 0.02),
               rel_error_metric("dp", last["dp"], ST_2D1["dp"], 0.03),
               report_only("c_L", last["c_L"], reference=ST_2D1["c_L"], note="no target in issue #5"),
               report_only("cells", float(last["cells"]), note="finest mesh (unfitted)"),
               report_only("h_cyl", h_cyl, unit="m", note="finest mesh"),
               report_only("area_error", last["area_error"], note="fitted fluid area vs exact, relative")]
    for r in fitted:
        if r[0] == h_cyl:
            metrics += [report_only("c_D_fitted", r[1], reference=ST_2D1["c_D"], note=f"body-fitted, {r[4]} cells"),
                        report_only("dp_fitted", r[3], reference=ST_2D1["dp"], note=f"body-fitted, {r[4]} cells")]
    return metrics


# ------------------------------------------------------------------------ 3D-1Z
# (h_cyl, h_far, band): quick, two meshes fine within 1.5 radii of the axis; full, three meshes with
# a shell of fine cells on both sides of the (unfitted) cylinder surface, |ρ − r| ≤ 2 h_cyl,
# growing to h_far at 0.15 m (mesh.channel.channel_unfitted)
CUT_3D_LEVELS = {"quick": [(0.03, 0.09, None), (0.02, 0.06, None)],
                 "full": [(h, 0.0225, (2 * h, 0.15)) for h in (0.01, 0.0075, 0.005)]}


@register("cylinder_3d1z_cut", "Schäfer–Turek 3D-1Z on an unfitted mesh (finite-cover cut, pressure wall): "
          "drag, pressure drop", issue=5)
def cylinder_3d1z_cut(level, out_dir: Path, comm) -> list[Metric]:
    from ...fluid.solvers import ITERATIVE_3D
    rows, last = [], None
    for h_cyl, h_far, band in CUT_3D_LEVELS[level]:
        t0 = time.perf_counter()
        last = cut_cylinder_solution(comm, 3, h_cyl, h_far, petsc=ITERATIVE_3D, band=band)
        rows.append(_row(h_cyl, last, time.perf_counter() - t0))
        log.info("3D-1Z cut h_cyl %g: c_D %.5f c_L %.5f dp %.5f cells %d (%.1f s)", *rows[-1])
    if comm.rank == 0:
        for r in rows:
            print(f"  cut h_cyl {r[0]:<7g} cells {r[4]:>7d}  c_D {r[1]:.5f}  c_L {r[2]:.5f}  dp {r[3]:.5f}  {r[5]:.1f} s")
        if len(rows) > 1:
            plot_cylinder_convergence(rows, ST_3D1Z, ("c_D", "dp"), out_dir / "cylinder_3d1z_cut_convergence.png",
                                      label="cut (wall traction)")
    if level == "quick":
        # 7.8k and 25k tetrahedra are far too coarse for the 3 % targets (c_D +22.3 / +19.1 %, Δp
        # −20.8 / −9.0 %): checked is their convergence toward the reference. Δp at no less than
        # first order (observed 2.07); c_D only in direction (observed order 0.39: on these meshes the
        # cut cells carry much of the wall and the drag converges slowly until h_cyl ≈ 0.01, from
        # where the full level's shell meshes show order ≈ 1.9)
        (h1, cd1, _, dp1, *_), (h2, *_) = rows
        return [error_order("c_D_order", cd1, last["c_D"], ST_3D1Z["c_D"], h1 / h2, 0.0),
                error_order("dp_order", dp1, last["dp"], ST_3D1Z["dp"], h1 / h2, 1.0),
                report_only("c_D", last["c_D"], reference=ST_3D1Z["c_D"], note="h_cyl 0.02: the 3 % target is the full level's"),
                report_only("dp", last["dp"], reference=ST_3D1Z["dp"], note="h_cyl 0.02: the 3 % target is the full level's"),
                report_only("c_L", last["c_L"], reference=ST_3D1Z["c_L"], note="no target in issue #5"),
                report_only("cells", float(last["cells"]), note="finest mesh (unfitted)"),
                report_only("volume_error", last["area_error"], note="fitted fluid volume vs exact, relative")]
    return [rel_error_metric("c_D", last["c_D"], ST_3D1Z["c_D"], 0.03),
            rel_error_metric("dp", last["dp"], ST_3D1Z["dp"], 0.03),
            report_only("c_L", last["c_L"], reference=ST_3D1Z["c_L"], note="no target in issue #5"),
            report_only("cells", float(last["cells"]), note="finest mesh (unfitted)"),
            report_only("h_cyl", CUT_3D_LEVELS[level][-1][0], unit="m", note="finest mesh"),
            report_only("volume_error", last["area_error"], note="fitted fluid volume vs exact, relative")]
