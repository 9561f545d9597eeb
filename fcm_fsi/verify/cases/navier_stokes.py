"""Verification of the stabilized Navier–Stokes solver (issue #3).

taylor_green: decaying vortex with exact solution — spatial and temporal orders.
cavity_re100 / cavity_re1000: steady lid-driven cavity vs Ghia, Ghia & Shin (1982).
cylinder_2d1 / cylinder_2d2 / cylinder_3d1z: Schäfer & Turek (1996) channel benchmarks.
"""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from ... import jit
from ...config.fluid import BoundaryCondition, FluidConfig, StabilizationConfig
from ...fluid.forces import ReactionForce, probe
from ...fluid.navier_stokes import NavierStokes
from ...fluid.steady import march_to_steady
from ...io.logging import get_logger
from ...mesh import channel
from ..registry import Metric, at_least, at_most, error_order, in_interval, register, rel_error_metric, report_only

log = get_logger("verify.navier_stokes")

# ---------------------------------------------------------------- reference data
# Ghia, Ghia & Shin (1982), J. Comput. Phys. 48:387–411, Table I (u on x = 0.5) and
# Table II (v on y = 0.5); cross-checked against several public transcriptions.
GHIA_Y = np.array([1.0000, 0.9766, 0.9688, 0.9609, 0.9531, 0.8516, 0.7344, 0.6172, 0.5000,
                   0.4531, 0.2813, 0.1719, 0.1016, 0.0703, 0.0625, 0.0547, 0.0000])
GHIA_U = {100: [1.0, 0.84123, 0.78871, 0.73722, 0.68717, 0.23151, 0.00332, -0.13641, -0.20581,
                -0.21090, -0.15662, -0.10150, -0.06434, -0.04775, -0.04192, -0.03717, 0.0],
          1000: [1.0, 0.65928, 0.57492, 0.51117, 0.46604, 0.33304, 0.18719, 0.05702, -0.06080,
                 -0.10648, -0.27805, -0.38289, -0.29730, -0.22220, -0.20196, -0.18109, 0.0]}
GHIA_X = np.array([1.0000, 0.9688, 0.9609, 0.9531, 0.9453, 0.9063, 0.8594, 0.8047, 0.5000,
                   0.2344, 0.2266, 0.1563, 0.0938, 0.0781, 0.0703, 0.0625, 0.0000])
GHIA_V = {100: [0.0, -0.05906, -0.07391, -0.08864, -0.10313, -0.16914, -0.22445, -0.24533, 0.05454,
                0.17527, 0.17507, 0.16077, 0.12317, 0.10890, 0.10091, 0.09233, 0.0],
          1000: [0.0, -0.21388, -0.27669, -0.33714, -0.39188, -0.51550, -0.42665, -0.31966, 0.02526,
                 0.32235, 0.33075, 0.37095, 0.32627, 0.30353, 0.29012, 0.27485, 0.0]}

# Schäfer & Turek (1996) reference values (FEATFLOW high-resolution values for 2D-1 and 3D-1Z).
ST_2D1 = {"c_D": 5.57953523384, "c_L": 0.010618948146, "dp": 0.11752016697}
ST_2D2 = {"strouhal": (0.295, 0.305), "c_D_max": 3.23, "c_L_max": 1.00}
ST_3D1Z = {"c_D": 6.185333, "c_L": 0.009401, "dp": 0.171007}


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _order(h: np.ndarray, e: np.ndarray) -> np.ndarray:
    return np.log(e[:-1] / e[1:]) / np.log(h[:-1] / h[1:])


# ------------------------------------------------------------------ Taylor–Green
def _tg_exact(nu: float):
    def u(x, t):
        d = np.exp(-2 * np.pi ** 2 * nu * t)
        return np.vstack([-np.cos(np.pi * x[0]) * np.sin(np.pi * x[1]) * d,
                          np.sin(np.pi * x[0]) * np.cos(np.pi * x[1]) * d])
    return u


def _taylor_green_run(comm, n: int, dt: float, t_end: float, nu: float, tm=None, nonlinear: str = "newton"):
    """Solve TG on [0,1]² with exact Dirichlet data; returns (solver, L2 velocity error at t_end).

    Pass the same ``tm`` to compare runs node by node (the partition is then identical).
    """
    if tm is None:
        tm = channel.rectangle(comm, (0.0, 0.0), (1.0, 1.0), (n, n), diagonal="crossed")
    cfg = FluidConfig(density=1.0, viscosity=nu, rtol=1e-10, atol=1e-13, nonlinear=nonlinear)
    exact = _tg_exact(nu)
    ns = NavierStokes(tm.mesh, cfg, dt, facet_tags=tm.facet_tags, boundary_names=tm.names,
                      velocity_functions={b: exact for b in tm.names})
    ns.set_velocity(lambda x: exact(x, 0.0))
    nsteps = int(round(t_end / dt))
    for _ in range(nsteps):
        ns.step()
    x = ufl.SpatialCoordinate(tm.mesh)
    d = np.exp(-2 * np.pi ** 2 * nu * ns.t)
    ue = ufl.as_vector([-ufl.cos(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1]) * d,
                        ufl.sin(ufl.pi * x[0]) * ufl.cos(ufl.pi * x[1]) * d])
    u, _ = ns.split(ns.U)
    err2 = fem.assemble_scalar(jit.form(ufl.inner(u - ue, u - ue) * ufl.dx(metadata={"quadrature_degree": 6})))
    return ns, float(np.sqrt(comm.allreduce(err2, op=MPI.SUM)))


def _l2_diff(ns_a: NavierStokes, ns_b: NavierStokes) -> float:
    """‖u_a − u_b‖_L2 for two solutions on the same mesh."""
    diff = fem.Function(ns_a.V)
    diff.x.array[:] = ns_a.U.x.array[ns_a.V_map] - ns_b.U.x.array[ns_b.V_map]
    e2 = fem.assemble_scalar(jit.form(ufl.inner(diff, diff) * ufl.dx(metadata={"quadrature_degree": 2})))
    return float(np.sqrt(ns_a.comm.allreduce(e2, op=MPI.SUM)))


@register("taylor_green", "2D Taylor–Green vortex, exact solution: observed orders in space and time", issue=3)
def taylor_green(level, out_dir: Path, comm) -> list[Metric]:
    nu = 0.01
    ns_space = [8, 16, 32] if level == "quick" else [16, 32, 64]
    dt_s, t_end_s = 0.01, 0.2
    errs = np.array([_taylor_green_run(comm, n, dt_s, t_end_s, nu)[1] for n in ns_space])
    hs = 1.0 / np.array(ns_space)
    p_space = _order(hs, errs)
    # time: same mesh, dt halved; differences of successive solutions cancel the spatial error.
    # At ν = 0.01 the CN error of this slowly decaying field (≤ 1e-5) is below the Δt-dependence
    # of the stabilized spatial operator, so the temporal study uses ν = 0.1 (decay e^{-2π²νt}).
    nu_t = 0.1
    n_t = 32 if level == "quick" else 64
    t_end_t = 1.0
    dts = np.array([0.2, 0.1, 0.05, 0.025])
    tm = channel.rectangle(comm, (0.0, 0.0), (1.0, 1.0), (n_t, n_t), diagonal="crossed")
    runs = [_taylor_green_run(comm, n_t, dt, t_end_t, nu_t, tm) for dt in dts]
    diffs = np.array([_l2_diff(runs[i][0], runs[i + 1][0]) for i in range(len(runs) - 1)])
    p_time = np.log(diffs[:-1] / diffs[1:]) / np.log(2.0)
    terr = np.array([r[1] for r in runs])
    log.info("TG space errors %s orders %s; time diffs %s orders %s", errs, p_space, diffs, p_time)
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
        ax[0].loglog(hs, errs, "o-", label=f"‖u − u_exact‖ (dt = {dt_s:g}, ν = {nu:g})")
        ax[0].loglog(hs, errs[0] * (hs / hs[0]) ** 2, "k--", label="slope 2")
        ax[0].set_xlabel("h"), ax[0].set_ylabel("L2 error"), ax[0].legend(), ax[0].set_title("space")
        ax[1].loglog(dts[:-1], diffs, "o-", label=f"‖u_dt − u_dt/2‖ (N = {n_t:d}, ν = {nu_t:g})")
        ax[1].loglog(dts, terr, "s:", label="‖u_dt − u_exact‖")
        ax[1].loglog(dts[:-1], diffs[0] * (dts[:-1] / dts[0]) ** 2, "k--", label="slope 2")
        ax[1].set_xlabel("Δt"), ax[1].legend(), ax[1].set_title("time (Crank–Nicolson)")
        fig.tight_layout()
        fig.savefig(out_dir / "taylor_green_orders.png", dpi=110)
        plt.close(fig)
    return [at_least("order_space", float(p_space[-1]), 1.8),
            at_least("order_time", float(p_time[-1]), 1.8),
            report_only("l2_error_finest", float(errs[-1]), note=f"N = {ns_space[-1]}, t = {t_end_s}"),
            report_only("time_diffs_last", float(diffs[-1]), note=f"‖u_dt − u_dt/2‖, dt = {dts[-2]:g}, ν = {nu_t:g}")]


# ----------------------------------------------------------------------- cavity
def cavity_solution(comm, re: float, n: int):
    """Steady lid-driven unit cavity (lid speed 1, ν = 1/Re) by backward-Euler pseudo-time marching."""
    tm = channel.rectangle(comm, (0.0, 0.0), (1.0, 1.0), (n, n), diagonal="crossed")
    bcs = (BoundaryCondition(boundary="ymax", kind="velocity", value=(1.0, 0.0)),
           BoundaryCondition(boundary="xmin", kind="no_slip"),
           BoundaryCondition(boundary="xmax", kind="no_slip"),
           BoundaryCondition(boundary="ymin", kind="no_slip"))
    cfg = FluidConfig(density=1.0, viscosity=1.0 / re, boundaries=bcs, theta=1.0, rtol=1e-9, atol=1e-12,
                      stabilization=StabilizationConfig(time_term=False))
    ns = NavierStokes(tm.mesh, cfg, 1.0, facet_tags=tm.facet_tags, boundary_names=tm.names)
    steps = march_to_steady(ns, tol=1e-7, max_steps=200, growth=1.5, dt_max=1e4)
    return ns, steps


def _cavity_case(re: int, level, out_dir: Path, comm, tol: float) -> list[Metric]:
    n = {100: {"quick": 64, "full": 128}, 1000: {"quick": 64, "full": 128}}[re][level]
    t0 = time.perf_counter()
    ns, steps = cavity_solution(comm, re, n)
    u = ns.u
    pu = np.c_[np.full_like(GHIA_Y, 0.5), GHIA_Y, np.zeros_like(GHIA_Y)]
    pv = np.c_[GHIA_X, np.full_like(GHIA_X, 0.5), np.zeros_like(GHIA_X)]
    u_c = probe(u, pu)[:, 0]
    v_c = probe(u, pv)[:, 1]
    dev = max(np.abs(u_c - GHIA_U[re]).max(), np.abs(v_c - GHIA_V[re]).max())
    wall = time.perf_counter() - t0
    s = np.linspace(0, 1, 201)
    line_u = probe(u, np.c_[np.full(201, 0.5), np.linspace(0, 1, 201), np.zeros(201)])[:, 0]
    line_v = probe(u, np.c_[np.linspace(0, 1, 201), np.full(201, 0.5), np.zeros(201)])[:, 1]
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(9, 4))
        ax[0].plot(line_u, s, "-", label=f"P1/P1 SUPG/PSPG/LSIC {n}×{n}")
        ax[0].plot(GHIA_U[re], GHIA_Y, "ko", mfc="none", label="Ghia et al. 1982")
        ax[0].set_xlabel("u(0.5, y)"), ax[0].set_ylabel("y"), ax[0].legend(fontsize=8)
        ax[1].plot(s, line_v, "-")
        ax[1].plot(GHIA_X, GHIA_V[re], "ko", mfc="none")
        ax[1].set_xlabel("x"), ax[1].set_ylabel("v(x, 0.5)")
        fig.suptitle(f"lid-driven cavity Re = {re}: max |dev| = {dev:.4f}")
        fig.tight_layout()
        fig.savefig(out_dir / f"cavity_re{re}_centrelines.png", dpi=110)
        plt.close(fig)
    return [at_most("ghia_max_dev", float(dev), tol),
            report_only("pseudo_time_steps", float(steps), note=f"{n}×{n} crossed, {wall:.1f} s")]


@register("cavity_re100", "lid-driven cavity Re 100 vs Ghia et al. (1982) centrelines", issue=3)
def cavity_re100(level, out_dir: Path, comm) -> list[Metric]:
    return _cavity_case(100, level, out_dir, comm, 0.01)


@register("cavity_re1000", "lid-driven cavity Re 1000 vs Ghia et al. (1982) centrelines", issue=3)
def cavity_re1000(level, out_dir: Path, comm) -> list[Metric]:
    return _cavity_case(1000, level, out_dir, comm, 0.02)


# ------------------------------------------------------------ Schäfer–Turek 2D-1
def channel_config(um: float, theta: float, time_term: bool, petsc: dict | None = None) -> FluidConfig:
    bcs = (BoundaryCondition(boundary="inlet", kind="parabolic_inflow", max_speed=um),
           BoundaryCondition(boundary="walls", kind="no_slip"),
           BoundaryCondition(boundary="cylinder", kind="no_slip"),
           BoundaryCondition(boundary="outlet", kind="do_nothing"))
    kw = {"petsc": petsc} if petsc else {}
    return FluidConfig(density=1.0, viscosity=1e-3, boundaries=bcs, theta=theta, rtol=1e-9, atol=1e-12,
                       stabilization=StabilizationConfig(time_term=time_term), **kw)


def cylinder_2d1_solution(comm, h_cyl: float, h_far: float):
    """Steady Re 20 flow (U_m = 0.3): returns (c_D, c_L, Δp, number of cells)."""
    tm = channel.channel_2d(comm, h_cyl=h_cyl, h_far=h_far)
    ns = NavierStokes(tm.mesh, channel_config(0.3, 1.0, False), 1.0,
                      facet_tags=tm.facet_tags, boundary_names=tm.names)
    march_to_steady(ns, tol=1e-8, max_steps=100, growth=2.0, dt_max=1e4)
    force = ReactionForce(ns.W, ns.F_form, ns.boundary_facets("cylinder"))()
    u_mean, diam = 0.2, 0.1
    c_d, c_l = 2 * force / (1.0 * u_mean ** 2 * diam)
    p = probe(ns.p, np.array([[0.15, 0.2, 0.0], [0.25, 0.2, 0.0]]))
    ncells = comm.allreduce(tm.mesh.topology.index_map(2).size_local, op=MPI.SUM)
    return float(c_d), float(c_l), float(p[0] - p[1]), ncells



def plot_cylinder_convergence(rows, reference: dict, keys: tuple[str, ...], path,
                              label: str = "P1/P1 reaction force", compare: dict | None = None) -> None:
    """c_D / c_L / Δp against the cell size at the cylinder (rows: (h, c_D, c_L, Δp, cells)),
    refinement to the right, cell counts under the ticks, with the Schäfer–Turek values;
    ``compare`` adds further series {label: rows}; rank 0."""
    plt = _plt()
    from matplotlib.ticker import NullFormatter
    columns = {"c_D": 1, "c_L": 2, "dp": 3}
    fig, ax = plt.subplots(1, len(keys), figsize=(4 * len(keys), 3.6))
    series = {label: rows, **(compare or {})}
    for a, key in zip(ax, keys):
        for (name, rs), style in zip(series.items(), ("o-", "s--", "^:", "v-.")):
            a.semilogx([r[0] for r in rs], [r[columns[key]] for r in rs], style, label=name)
        a.axhline(reference[key], color="k", ls="--", label="Schäfer–Turek")
        a.set_xticks([r[0] for r in rows])
        a.set_xticklabels([f"{r[0]:g}\n{r[4] / 1000:.0f}k" for r in rows], fontsize=8)
        a.xaxis.set_minor_formatter(NullFormatter())
        a.invert_xaxis()
        a.set_xlabel("h at the cylinder [m] / cells"), a.set_title(key)
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


@register("cylinder_2d1", "Schäfer–Turek 2D-1 (Re 20, steady): drag, lift, pressure drop", issue=3)
def cylinder_2d1(level, out_dir: Path, comm) -> list[Metric]:
    levels = [(0.0025, 0.01)] if level == "quick" else [(0.01, 0.04), (0.005, 0.02), (0.0025, 0.01)]
    rows = []
    for h_cyl, h_far in levels:
        t0 = time.perf_counter()
        rows.append((h_cyl,) + cylinder_2d1_solution(comm, h_cyl, h_far) + (time.perf_counter() - t0,))
        log.info("2D-1 h_cyl %g: c_D %.6f c_L %.6f dp %.6f cells %d (%.1f s)", *rows[-1])
    c_d, c_l, dp, ncells = rows[-1][1:5]
    if comm.rank == 0:
        plot_cylinder_convergence(rows, ST_2D1, ("c_D", "c_L", "dp"), out_dir / "cylinder_2d1_convergence.png")
    return [rel_error_metric("c_D", c_d, ST_2D1["c_D"], 0.005),
            rel_error_metric("dp", dp, ST_2D1["dp"], 0.01),
            rel_error_metric("c_L", c_l, ST_2D1["c_L"], 0.10),
            report_only("cells", float(ncells), note="finest mesh")]


# ------------------------------------------------------------ Schäfer–Turek 2D-2
def cylinder_2d2_history(comm, h_cyl: float, h_far: float, dt: float, t_end: float):
    """Re 100 (U_m = 1.5), Crank–Nicolson from rest with a 0.5 s inflow ramp.

    The symmetric start is broken by spinning the cylinder for t < 1 s (surface speed up
    to 0.3 m/s, then exactly 0); the periodic state is measured long after that.
    Returns arrays t, c_D, c_L (forces at t^{n+1/2}).
    """
    tm = channel.channel_2d(comm, h_cyl=h_cyl, h_far=h_far)
    cfg = dataclasses.replace(channel_config(1.5, 0.5, True), boundaries=(
        BoundaryCondition(boundary="inlet", kind="parabolic_inflow", max_speed=1.5, ramp_time=0.5),
        BoundaryCondition(boundary="walls", kind="no_slip"),
        BoundaryCondition(boundary="outlet", kind="do_nothing")))

    def spin(x, t):
        omega = 6.0 * np.sin(np.pi * t) if t < 1.0 else 0.0
        return np.vstack([-omega * (x[1] - 0.2), omega * (x[0] - 0.2)])
    ns = NavierStokes(tm.mesh, cfg, dt, facet_tags=tm.facet_tags, boundary_names=tm.names,
                      velocity_functions={"cylinder": spin})
    force = ReactionForce(ns.W, ns.F_form, ns.boundary_facets("cylinder"))
    ts, cd, cl = [], [], []
    nsteps = int(round(t_end / dt))
    for k in range(nsteps):
        ns.step()
        f = force()
        ts.append(ns.t - 0.5 * dt)
        cd.append(2 * f[0] / (1.0 * 1.0 ** 2 * 0.1))
        cl.append(2 * f[1] / (1.0 * 1.0 ** 2 * 0.1))
        if (k + 1) % 100 == 0:
            log.info("2D-2 t = %.3f  c_D = %.4f  c_L = %.4f", ns.t, cd[-1], cl[-1])
    return np.array(ts), np.array(cd), np.array(cl)


def _strouhal(t: np.ndarray, cl: np.ndarray, diam: float = 0.1, u_mean: float = 1.0) -> float:
    """St = D f / Ū from the mean period between upward zero crossings of c_L (linear interpolation)."""
    c = cl - 0.5 * (cl.max() + cl.min())
    idx = np.flatnonzero((c[:-1] < 0) & (c[1:] >= 0))
    tz = t[idx] - c[idx] * (t[idx + 1] - t[idx]) / (c[idx + 1] - c[idx])
    if len(tz) < 2:
        return float("nan")
    return diam / (np.diff(tz).mean() * u_mean)


@register("cylinder_2d2", "Schäfer–Turek 2D-2 (Re 100, periodic): Strouhal number, max drag and lift", issue=3)
def cylinder_2d2(level, out_dir: Path, comm) -> list[Metric]:
    """Full: h_cyl 0.0035, Δt 0.005 to 6 s against the three targets. Quick: h_cyl 0.005,
    Δt 0.01 to 4.5 s, whose c_D,max is +1.26 % off (target 1 %; the full level +0.41 %): checked
    instead is its convergence from a coarser run (h_cyl 0.007, Δt 0.014: +2.62 %) at no less
    than first order (observed 2.2, Crank–Nicolson and P1 being second order); St and c_L,max
    meet their targets at the quick resolution and keep them."""
    h_cyl, h_far, dt, t_end = (0.005, 0.02, 0.01, 4.5) if level == "quick" else (0.0035, 0.014, 0.005, 6.0)
    coarse = None
    if level == "quick":      # the same run 1.4 × coarser in space and time
        t, cd, cl = cylinder_2d2_history(comm, 1.4 * h_cyl, 1.4 * h_far, 1.4 * dt, t_end)
        coarse = float(cd[t >= t_end - 1.5].max())
        log.info("2D-2 coarse h_cyl %g dt %g: c_D,max %.5f", 1.4 * h_cyl, 1.4 * dt, coarse)
    t0 = time.perf_counter()
    t, cd, cl = cylinder_2d2_history(comm, h_cyl, h_far, dt, t_end)
    wall = time.perf_counter() - t0
    window = t >= t_end - 1.5            # last ~4.5 periods
    st = _strouhal(t[window], cl[window])
    cd_max, cl_max = float(cd[window].max()), float(cl[window].max())
    if comm.rank == 0:
        plt = _plt()
        fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
        ax[0].plot(t, cd), ax[0].axhline(ST_2D2["c_D_max"], color="k", ls="--", label="S–T c_D,max 3.22–3.24")
        ax[0].set_ylim(3.0, 3.4), ax[0].set_ylabel("c_D"), ax[0].legend(fontsize=8)
        ax[1].plot(t, cl), ax[1].axhline(ST_2D2["c_L_max"], color="k", ls="--", label="S–T c_L,max 0.99–1.01")
        ax[1].set_ylabel("c_L"), ax[1].set_xlabel("t (s)"), ax[1].legend(fontsize=8)
        fig.suptitle(f"2D-2: St = {st:.4f}, c_D,max = {cd_max:.4f}, c_L,max = {cl_max:.4f} (h_cyl {h_cyl}, dt {dt})")
        fig.tight_layout()
        fig.savefig(out_dir / "cylinder_2d2_forces.png", dpi=110)
        plt.close(fig)
    drag = ([error_order("c_D_max_order", coarse, cd_max, ST_2D2["c_D_max"], 1.4, 1.0),
             report_only("c_D_max", cd_max, reference=ST_2D2["c_D_max"], note="the 1 % target is the full level's")]
            if level == "quick" else [rel_error_metric("c_D_max", cd_max, ST_2D2["c_D_max"], 0.01)])
    return [in_interval("strouhal", st, *ST_2D2["strouhal"]),
            *drag,
            rel_error_metric("c_L_max", cl_max, ST_2D2["c_L_max"], 0.03),
            report_only("wall_seconds", wall, unit="s", note=f"h_cyl {h_cyl}, dt {dt}, t_end {t_end}")]


# ------------------------------------------------------------ Schäfer–Turek 3D-1Z
def cylinder_3d1z_solution(comm, h_cyl: float, h_far: float, petsc: dict,
                           band: tuple[float, float] | None = None):
    """Steady Re 20 flow in the square channel (U_m = 0.45, Ū = 0.2): (c_D, c_L, Δp, cells).
    ``band``: the shell grading of ``channel.channel_3d``."""
    tm = channel.channel_3d(comm, h_cyl=h_cyl, h_far=h_far, band=band)
    cfg = dataclasses.replace(channel_config(0.45, 1.0, False, petsc), rtol=1e-7)
    ns = NavierStokes(tm.mesh, cfg, 0.5, facet_tags=tm.facet_tags, boundary_names=tm.names)
    march_to_steady(ns, tol=1e-6, max_steps=60, growth=2.0, dt_max=1e3)
    force = ReactionForce(ns.W, ns.F_form, ns.boundary_facets("cylinder"))()
    scale = 2.0 / (1.0 * 0.2 ** 2 * 0.1 * 0.41)
    p = probe(ns.p, np.array([[0.45, 0.2, 0.205], [0.55, 0.2, 0.205]]))
    ncells = tm.mesh.topology.index_map(3).size_global
    return float(scale * force[0]), float(scale * force[1]), float(p[0] - p[1]), ncells


@register("cylinder_3d1z", "Schäfer–Turek 3D-1Z (Re 20, steady, square channel): drag and pressure drop", issue=3)
def cylinder_3d1z(level, out_dir: Path, comm) -> list[Metric]:
    """Quick: two coarse meshes graded from the cylinder over the channel (h_cyl 0.03 and 0.02,
    7.8k and 24k tetrahedra), far too coarse for the 2 %/3 % targets (c_D +25.5 / +16.3 %, Δp
    −13.0 / −7.9 %): the check is their convergence toward the reference at no less than first
    order (the least P1/P1 gives for these functionals; observed 1.10 and 1.23). Full: three meshes with
    a shell of fine cells (h_cyl within 2 h_cyl of the surface, growing to h_far = 0.0225 at
    0.15 m): Δp is two point values of the wall pressure and converges like the wall cell size
    (2D-1 on the same grading: −3.3 / −2.4 / −0.8 % at h_cyl 0.0075 / 0.005 / 0.0025), so the
    cells go where it is decided."""
    from ...fluid.solvers import SCHUR_AMG
    levels = ([(0.03, 0.09, None), (0.02, 0.06, None)] if level == "quick" else
              [(h, 0.0225, (2 * h, 0.15)) for h in (0.01, 0.0075, 0.005)])
    rows = []
    for h_cyl, h_far, band in levels:
        t0 = time.perf_counter()
        rows.append((h_cyl,) + cylinder_3d1z_solution(comm, h_cyl, h_far, SCHUR_AMG, band)
                    + (time.perf_counter() - t0,))
        log.info("3D-1Z h_cyl %g: c_D %.5f c_L %.5f dp %.5f cells %d (%.1f s)", *rows[-1])
    c_d, c_l, dp, ncells = rows[-1][1:5]
    if comm.rank == 0:
        for r in rows:
            print(f"  h_cyl {r[0]:<7g} cells {r[4]:>7d}  c_D {r[1]:.5f}  c_L {r[2]:.5f}  dp {r[3]:.5f}  {r[5]:.1f} s")
        plot_cylinder_convergence(rows, ST_3D1Z, ("c_D", "dp"), out_dir / "cylinder_3d1z_convergence.png")
    if level == "quick":       # coarse meshes: the trend toward the reference, not the targets
        (h1, cd1, _, dp1, *_), (h2, *_) = rows
        return [error_order("c_D_order", cd1, c_d, ST_3D1Z["c_D"], h1 / h2, 1.0),
                error_order("dp_order", dp1, dp, ST_3D1Z["dp"], h1 / h2, 1.0),
                report_only("c_D", c_d, reference=ST_3D1Z["c_D"], note="h_cyl 0.02: the 2 % target is the full level's"),
                report_only("dp", dp, reference=ST_3D1Z["dp"], note="h_cyl 0.02: the 3 % target is the full level's"),
                report_only("c_L", c_l, reference=ST_3D1Z["c_L"], note="no target in issue #3"),
                report_only("cells", float(ncells), note="finest mesh")]
    return [rel_error_metric("c_D", c_d, ST_3D1Z["c_D"], 0.02),
            rel_error_metric("dp", dp, ST_3D1Z["dp"], 0.03),
            report_only("c_L", c_l, reference=ST_3D1Z["c_L"], note="no target in issue #3"),
            report_only("cells", float(ncells), note="finest mesh")]
