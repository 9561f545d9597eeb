"""DEM verification (issue #6): bounce, incline, free_rotation, chain_wave, repose.

Every case builds its model through the ``dem`` case schema (so the config path is
exercised too), runs on every rank identically, and writes its plot on rank 0.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ...config.dem import DEMConfig
from ...config.loader import build
from ...dem.model import build_system
from ...dem.restitution import damping_ratio, restitution_clipped, restitution_unclipped
from ...io.logging import get_logger
from ..plotting import save_figure
from ..registry import at_least, at_most, in_interval, register, rel_error_metric, report_only

log = get_logger("verify.dem")


def _cfg(data: dict) -> DEMConfig:
    return build(DEMConfig, data, source="<verify>", prefix="dem")


# ------------------------------------------------------------------------- bounce
def _sphere_on_floor(e: float, clip: bool, gravity, v0: float, z0: float, frac: float,
                     k: float = 1e5, r: float = 0.01, rho: float = 2500.0):
    mat = {"name": "m", "stiffness": k, "restitution": e, "friction_angle": 0.0, "density": rho}
    cfg = _cfg({"dt": 1.0, "dt_safety": 1.0, "gravity": list(gravity), "clip_normal": clip, "materials": [mat],
                "blocks": [{"shape": "sphere", "material": "m", "radius": r, "position": [0, 0, z0],
                            "velocity": [0, 0, -v0]}],
                "walls": [{"kind": "plane", "material": "m", "point": [0, 0, 0], "normal": [0, 0, 1]}]})
    # dt from Δt_cr: build with a tiny dt, then set dt = Δt_cr/frac and re-check it
    import dataclasses

    from ...dem.model import check_time_step
    system = build_system(dataclasses.replace(cfg, dt=1e-12))
    system.dt = system.critical_time_step() / frac
    check_time_step(system, cfg.dt_safety)
    return system


def _measure_restitution(e: float, clip: bool, frac: float) -> tuple[float, float]:
    """Measured e = v_out/v_in of one normal impact without gravity, and the prediction."""
    v0, r = 1.0, 0.01
    s = _sphere_on_floor(e, clip, (0, 0, 0), v0, r + 0.002, frac, r=r)
    st = s.state
    seen = False
    for _ in range(200000):
        s.step()
        touching = st.sph_pos[0, 2] < r
        seen |= touching
        if seen and not touching and st.vel[0, 2] > 0 and s.interactions[1].hist[0, 0, 3] == 0.0:
            break
    v_out = st.vel[0, 2]
    h = damping_ratio(e)
    pred = restitution_clipped(h) if clip else restitution_unclipped(h)
    return v_out / v0, pred


@register("bounce", "sphere on a floor: restitution vs the contact model, energy ledger with e = 1", issue=6)
def bounce(level, out_dir: Path, comm) -> list:
    frac = 10.0
    frac_e = 100.0   # restitution: contact resolved by ~150–300 steps (the switch error is O(Δt))
    rows = []
    for clip in (True, False):
        for e in (0.2, 0.5, 0.9):
            meas, pred = _measure_restitution(e, clip, frac_e)
            rows.append((clip, e, meas, pred, abs(meas - pred) / pred))
    worst = max(r[4] for r in rows if r[0])
    metrics = [at_most("restitution_rel_error", worst, 0.01)]
    sweep = {}
    for fr in ((10.0, 20.0, 40.0, 80.0) if level == "full" else (10.0,)):
        sweep[fr] = max(abs(m - p) / p for m, p in (_measure_restitution(e, True, fr) for e in (0.2, 0.5, 0.9)))
        metrics.append(report_only(f"restitution_rel_error_dt_cr/{fr:g}", sweep[fr],
                                   note="worst of e = 0.2, 0.5, 0.9 (clipped model) at this dt"))
    for clip, e, meas, pred, err in rows:
        metrics.append(report_only(f"restitution_{'clip' if clip else 'noclip'}_e{e:g}", meas, reference=pred,
                                   note=f"rel. error {err:.2e} vs the {'clipped' if clip else 'unclipped'} model"))
    worst_nc = max(r[4] for r in rows if not r[0])
    metrics.append(report_only("restitution_rel_error_noclip", worst_nc, note="unclipped model vs eq 20"))

    # energy ledger: e = 1, no friction, 100 bounces at dt = Δt_cr/10, gravity on
    r, h0 = 0.01, 0.005
    g = 9.81
    s = _sphere_on_floor(1.0, True, (0, 0, -g), 0.0, r + h0, frac, r=r)
    st = s.state
    m = st.mass[0]
    E_ref = m * g * h0
    nb_, prev, t_b, bal = 0, False, [], []
    nmax = 100 if level == "full" else 100
    while nb_ < nmax:
        s.step()
        inc = st.sph_pos[0, 2] < r
        if prev and not inc:
            nb_ += 1
            t_b.append(st.t)
            bal.append(s.ledger.last["balance_error"] / E_ref)
        prev = inc
    bal = np.array(bal)
    metrics.append(at_most("energy_balance_error", abs(bal[-1]), 1e-4))
    metrics.append(report_only("energy_balance_error_max", float(np.abs(bal).max()),
                               note="largest |balance|/(m g h0) after any of the 100 bounces"))
    # convergence of the ledger error with dt (reported): dt = Δt_cr/20, /40
    conv = {}
    if level == "full":
        for fr in (20.0, 40.0):
            s2 = _sphere_on_floor(1.0, True, (0, 0, -g), 0.0, r + h0, fr, r=r)
            n2, p2, b2 = 0, False, []
            while n2 < 100:
                s2.step()
                inc = s2.state.sph_pos[0, 2] < r
                if p2 and not inc:
                    n2 += 1
                    b2.append(s2.ledger.last["balance_error"] / E_ref)
                p2 = inc
            conv[fr] = np.abs(b2).max()
            metrics.append(report_only(f"energy_balance_error_max_dt_cr/{fr:g}", conv[fr]))

    def draw(fig):
        ax1 = fig.add_subplot(1, 2, 1)
        for clip, mk in ((True, "o"), (False, "s")):
            sel = [x for x in rows if x[0] == clip]
            ax1.plot([x[1] for x in sel], [x[2] for x in sel], mk, label=f"measured ({'clipped' if clip else 'unclipped'})")
        ee = np.linspace(0.05, 1, 100)
        ax1.plot(ee, [restitution_clipped(damping_ratio(x)) for x in ee], "-", label="clipped model")
        ax1.plot(ee, ee, "--", label="eq 20 (unclipped)")
        ax1.set_xlabel("input e")
        ax1.set_ylabel("measured restitution")
        ax1.legend(fontsize=7)
        ax2 = fig.add_subplot(1, 2, 2)
        ax2.semilogy(np.arange(1, len(bal) + 1), np.abs(bal) + 1e-16, ".", label="dt = Δt_cr/10")
        ax2.axhline(1e-4, color="k", lw=0.8, label="target 1e-4")
        ax2.set_xlabel("bounce")
        ax2.set_ylabel("|ledger balance| / (m g h0)")
        ax2.legend(fontsize=7)
    save_figure(out_dir, "bounce.png", comm, draw)
    return metrics


# ------------------------------------------------------------------------- incline
def _box_on_slope(theta_deg: float, phi_deg: float, frac: float = 10.0):
    """Solid box (0.1 × 0.1 × 0.04 m, 1 kg) resting on the plane z = 0 under gravity tilted
    by θ: slope-parallel axis x, normal z."""
    from ...dem.model import check_time_step
    th = math.radians(theta_deg)
    g = 9.81
    cfg = _cfg({"dt": 1e-12, "gravity": [g * math.sin(th), 0.0, -g * math.cos(th)],
                "materials": [{"name": "m", "stiffness": 1e6, "restitution": 0.5,
                               "friction_angle": phi_deg, "density": 2500.0}],
                "blocks": [{"shape": "box", "material": "m", "size": [0.1, 0.1, 0.04], "radius": 0.01,
                            "position": [0, 0, 0.02]}],
                "walls": [{"kind": "plane", "material": "m", "point": [0, 0, 0], "normal": [0, 0, 1]}]})
    s = build_system(cfg)
    s.dt = s.critical_time_step() / frac
    check_time_step(s, cfg.dt_safety)
    return s


def _slide(theta, phi, t_end):
    s = _box_on_slope(theta, phi)
    st = s.state
    n = int(round(t_end / s.dt))
    t = np.empty(n)
    x = np.empty(n)
    v = np.empty(n)
    for i in range(n):
        s.step()
        t[i], x[i], v[i] = st.t, st.pos[0, 0], st.vel[0, 0]
    return s, t, x, v


@register("incline", "box sliding down / sticking on an inclined plane vs g(sin θ − μ cos θ)", issue=6)
def incline(level, out_dir: Path, comm) -> list:
    g, phi = 9.81, 20.0
    mu = math.tan(math.radians(phi))
    thetas = (30.0,) if level == "quick" else (25.0, 30.0, 45.0)
    t_end = 0.4 if level == "quick" else 0.8
    metrics, curves = [], []
    worst = 0.0
    for th in thetas:
        s, t, x, v = _slide(th, phi, t_end)
        a_ref = g * (math.sin(math.radians(th)) - mu * math.cos(math.radians(th)))
        # v is the half-step velocity v_{n+1/2}: fit v against t − Δt/2 after the landing transient
        sel = t > 0.1
        a_meas = np.polyfit(t[sel] - 0.5 * s.dt, v[sel], 1)[0]
        err = abs(a_meas - a_ref) / a_ref
        worst = max(worst, err)
        metrics.append(report_only(f"accel_theta{th:g}", a_meas, unit="m/s^2", reference=a_ref,
                                   note=f"rel. error {err:.2e}"))
        curves.append((th, t, v, a_ref))
    metrics.insert(0, at_most("accel_rel_error", worst, 0.01))
    # stick: tan θ < μ
    th_s = 15.0
    s, t, x, v = _slide(th_s, phi, t_end)
    slide_ref = 0.5 * g * math.sin(math.radians(th_s)) * t_end ** 2   # frictionless distance
    disp = abs(x[-1] - x[0])
    metrics.append(at_most("stick_displacement_ratio", disp / slide_ref, 1e-4,
                           reference=0.0))
    metrics.append(report_only("stick_displacement", disp, unit="m",
                               note=f"θ = {th_s:g}° < φ = {phi:g}° (tan θ = {math.tan(math.radians(th_s)):.3f} < μ = {mu:.3f})"))

    def draw(fig):
        ax = fig.add_subplot(1, 1, 1)
        for th, tt, vv, a_ref in curves:
            ax.plot(tt, vv, lw=1.2, label=f"DEM θ = {th:g}°")
            ax.plot(tt, a_ref * tt, "k--", lw=0.8)
        ax.plot(t, v, lw=1.2, label=f"DEM θ = {th_s:g}° (sticks)")
        ax.plot([], [], "k--", lw=0.8, label="g(sin θ − μ cos θ) t")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("slope-parallel velocity [m/s]")
        ax.set_title(f"block on an incline, φ = {phi:g}°")
        ax.legend(fontsize=8)
    save_figure(out_dir, "incline.png", comm, draw)
    return metrics


# ------------------------------------------------------------------------- free rotation
def _qmul_np(p, q):
    w1, v1, w2, v2 = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])


def _rotor(omega0, dt):
    cfg = _cfg({"dt": dt, "gravity": [0, 0, 0],
                "materials": [{"name": "m", "stiffness": 1e6, "restitution": 1.0, "friction_angle": 0.0,
                               "density": 1000.0}],
                "blocks": [{"shape": "box", "material": "m", "size": [0.3, 0.2, 0.1], "radius": 0.05,
                            "position": [0, 0, 0], "omega": list(omega0)}]})
    return build_system(cfg, with_ledger=False)


@register("free_rotation", "torque-free asymmetric box spun near its intermediate axis (Dzhanibekov flips)", issue=6)
def free_rotation(level, out_dir: Path, comm) -> list:
    from ...geometry import quat_to_matrix_np
    W, eps = 10.0, 1e-3 * 10.0
    dt = 2e-4                       # Ω Δt = 2e-3
    t_end = 30.0 if level == "quick" else 120.0
    s = _rotor((eps, W, eps), dt)
    st = s.state
    L0 = st.angmom[0].copy()
    I = st.inertia[0]

    def energy():
        Lb = quat_to_matrix_np(st.quat[0]).T @ st.angmom[0]
        return 0.5 * np.sum(Lb * Lb / I), Lb

    T0, _ = energy()
    n = int(round(t_end / dt))
    every = 50
    ts, wb, dL, dT = [], [], [], []
    dLm = []   # L from the motion: ω from the quaternion change over one step, at the mid orientation
    for i in range(n):
        q_old = st.quat[0].copy()
        s.step()
        if i % every == 0:
            q_new = st.quat[0]
            dq = _qmul_np(np.array([q_old[0], *(-q_old[1:])]), q_new)
            w_b = 2.0 * dq[1:] / dt
            qm = (q_old + q_new) / np.linalg.norm(q_old + q_new)
            Lm = quat_to_matrix_np(qm) @ (I * w_b)
            dLm.append(np.linalg.norm(Lm - L0) / np.linalg.norm(L0))
            T, Lb = energy()
            ts.append(st.t)
            wb.append(Lb / I)
            dL.append(np.linalg.norm(st.angmom[0] - L0) / np.linalg.norm(L0))
            dT.append(abs(T - T0) / T0)
    wb = np.array(wb)
    flips = int(np.count_nonzero(np.diff(np.sign(wb[:, 1])) != 0))
    metrics = [at_most("angmom_drift", max(dL), 1e-6), at_most("energy_drift", max(dT), 1e-5),
               at_least("flips", float(flips), 4.0),
               report_only("angmom_from_motion_drift", max(dLm),
                           note="L rebuilt from the orientation change over one step (O(Δt²) estimate)")]

    def draw(fig):
        ax = fig.add_subplot(2, 1, 1)
        for k, lab in enumerate(("ω₁ (min I)", "ω₂ (intermediate)", "ω₃ (max I)")):
            ax.plot(ts, wb[:, k], lw=0.8, label=lab)
        ax.set_ylabel("body ω [rad/s]")
        ax.legend(fontsize=7, loc="upper right")
        ax.set_title(f"{flips} flips, Ω Δt = {W * dt:g}")
        ax2 = fig.add_subplot(2, 1, 2)
        ax2.semilogy(ts, np.maximum(dT, 1e-17), lw=0.8, label="|T − T₀|/T₀")
        ax2.semilogy(ts, np.maximum(dL, 1e-17), lw=0.8, label="|L − L₀|/|L₀|")
        ax2.axhline(1e-5, color="C0", ls="--", lw=0.6)
        ax2.axhline(1e-6, color="C1", ls="--", lw=0.6)
        ax2.set_xlabel("t [s]")
        ax2.legend(fontsize=7)
    save_figure(out_dir, "free_rotation.png", comm, draw)
    return metrics


# ------------------------------------------------------------------------- chain wave
def _bessel_peak(n: int, w0: float) -> float:
    """First maximum of v_n(t) = v0 J_2n(2 ω0 t), the exact continuous-time chain."""
    from scipy.optimize import minimize_scalar
    from scipy.special import jn_zeros, jv
    nu = 2 * n
    # first maximum of J_nu lies between nu and the first zero of J_nu
    z1 = jn_zeros(nu, 1)[0] if nu > 0 else 2.4048
    res = minimize_scalar(lambda z: -jv(nu, z), bounds=(max(nu, 1e-6), z1), method="bounded",
                          options={"xatol": 1e-12})
    return res.x / (2 * w0)


def _peak_time(t, v):
    """Time of the maximum of a sampled signal, refined by a parabola through 3 samples."""
    i = int(np.argmax(v))
    i = min(max(i, 1), len(v) - 2)
    y0, y1, y2 = v[i - 1], v[i], v[i + 1]
    den = y0 - 2 * y1 + y2
    off = 0.5 * (y0 - y2) / den if den != 0 else 0.0
    return t[i] + off * (t[1] - t[0])


@register("chain_wave", "1D chain of preloaded spheres: wave speed vs √(k/m)·dx with discrete dispersion", issue=6)
def chain_wave(level, out_dir: Path, comm) -> list:
    from ...dem.model import check_time_step
    N = 81 if level == "quick" else 161
    r, k, rho, delta0, v0 = 0.01, 1e5, 2500.0, 1e-3, 0.1
    dx = 2 * r - delta0
    blocks = [{"shape": "sphere", "material": "m", "radius": r, "position": [i * dx, 0, 0],
               "fixed": i in (0, N - 1)} for i in range(N)]
    cfg = _cfg({"dt": 1e-12, "gravity": [0, 0, 0], "materials": [{"name": "m", "stiffness": k, "restitution": 1.0,
                                                                      "friction_angle": 0.0, "density": rho}],
                "blocks": blocks})
    s = build_system(cfg, with_ledger=False)
    s.dt = s.critical_time_step() / 10
    check_time_step(s, cfg.dt_safety)
    st = s.state
    m = st.mass[1]
    w0 = math.sqrt(k / m)
    c0 = w0 * dx
    mid = N // 2
    st.vel[mid, 0] = v0
    n1, n2 = (5, 30) if level == "quick" else (10, 60)
    # stop before the front reflected at the fixed end (site mid ± (mid − 1)) returns to site n2
    t_stop = (2 * (mid - 1) - n2) / w0 * 0.9
    nsteps = int(t_stop / s.dt)
    t = np.empty(nsteps)
    v1 = np.empty(nsteps)
    v2 = np.empty(nsteps)
    for i in range(nsteps):
        s.step()
        # st.vel is v_{n+1/2}: time t − Δt/2
        t[i] = st.t - 0.5 * s.dt
        v1[i], v2[i] = st.vel[mid + n1, 0], st.vel[mid + n2, 0]
    tp1, tp2 = _peak_time(t, v1), _peak_time(t, v2)
    c_meas = (n2 - n1) * dx / (tp2 - tp1)
    r1, r2 = _bessel_peak(n1, w0), _bessel_peak(n2, w0)
    c_ref = (n2 - n1) * dx / (r2 - r1)
    metrics = [rel_error_metric("wave_speed_rel_error", c_meas, c_ref, 0.01, unit="m/s"),
               report_only("wave_speed_vs_continuum", c_meas, unit="m/s", reference=c0,
                           note=f"√(k/m)·dx = {c0:.4g}; rel. difference {abs(c_meas - c0) / c0:.3g} (dispersion)"),
               report_only("dt_over_dt_cr", s.dt / s.critical_time_step())]

    def draw(fig):
        from scipy.special import jv
        ax = fig.add_subplot(1, 1, 1)
        tt = np.linspace(0, t[-1], 2000)
        for n, vv, lab in ((n1, v1, f"site +{n1}"), (n2, v2, f"site +{n2}")):
            ax.plot(t * 1e3, vv / v0, lw=1.2, label=f"DEM {lab}")
            ax.plot(tt * 1e3, jv(2 * n, 2 * w0 * tt), "k--", lw=0.7)
        ax.plot([], [], "k--", lw=0.7, label="exact chain v₀ J₂ₙ(2ω₀t)")
        ax.set_xlabel("t [ms]")
        ax.set_ylabel("v / v₀")
        ax.set_title(f"c = {c_meas:.4g} m/s (chain {c_ref:.4g}, √(k/m)dx = {c0:.4g})")
        ax.legend(fontsize=8)
    save_figure(out_dir, "chain_wave.png", comm, draw)
    return metrics


# ------------------------------------------------------------------------- repose
R_CLUMP = 0.005


def repose_config(count: int, seed: int, dt: float = 2.5e-5, t_gate: float = 0.4, half_width: float = 0.1) -> dict:
    """Three-sphere clumps (r = 5 mm) settle in a 40 mm wide slot between two gates at
    x = ±half_width; the gates are removed at t_gate and the granular "dam" collapses
    into a heap whose flanks stand at the angle of repose (the same set-up as
    cases/dem_repose.yaml). Aspect ratio height/width < 0.7 keeps the flanks at repose."""
    r = R_CLUMP
    a = 2.0 * 1.69 * r * 1.05                       # lattice spacing of the generator
    per_layer = int((2 * half_width - 2 * 1.69 * r) / a + 1) * 2
    height = 0.0 + (count // per_layer + 2) * a
    def plane(p, n, until=None):
        return {"kind": "plane", "material": "grain", "point": p, "normal": n, "remove_at": until}
    return {"dt": dt, "gravity": [0, 0, -9.81],
            "materials": [{"name": "grain", "stiffness": 1e5, "restitution": 0.3, "friction_angle": 30.0,
                           "density": 2500.0}],
            "generators": [{"block": {"shape": "clump", "material": "grain", "position": [0, 0, 0],
                                      "spheres": [[0, 0, 0, r], [1.2 * r, 0, 0, r], [0.6 * r, 1.0 * r, 0, r]]},
                            "count": count, "region_min": [-half_width, 0.0, 0.0],
                            "region_max": [half_width, 0.04, height], "seed": seed}],
            "walls": [plane([0, 0, 0], [0, 0, 1]), plane([0, 0, 0], [0, 1, 0]), plane([0, 0.04, 0], [0, -1, 0]),
                      plane([-half_width, 0, 0], [1, 0, 0], t_gate), plane([half_width, 0, 0], [-1, 0, 0], t_gate),
                      plane([-0.6, 0, 0], [1, 0, 0]), plane([0.6, 0, 0], [-1, 0, 0])]}


def heap_angle(sph_pos, sph_radius, bin_width: float = 2 * R_CLUMP):
    """Angle of repose [deg] of a quasi-2D heap: the surface z_s(x) (top of the highest sphere
    per x bin) is fitted by a line on each flank between 20 % and 80 % of the peak height."""
    top = sph_pos[:, 2] + sph_radius
    x = sph_pos[:, 0]
    edges = np.arange(x.min() - bin_width, x.max() + 2 * bin_width, bin_width)
    idx = np.digitize(x, edges)
    xc, zs = [], []
    for k in np.unique(idx):
        sel = idx == k
        xc.append(0.5 * (edges[k - 1] + edges[k]))
        zs.append(top[sel].max())
    xc, zs = np.array(xc), np.array(zs)
    h = zs.max()
    ipk = int(np.argmax(zs))
    fits = []
    for side in (slice(0, ipk + 1), slice(ipk, len(xc))):
        xs, z = xc[side], zs[side]
        sel = (z > 0.2 * h) & (z < 0.8 * h)
        if np.count_nonzero(sel) >= 3:
            fits.append(np.polyfit(xs[sel], z[sel], 1))
    angles = [math.degrees(math.atan(abs(f[0]))) for f in fits]
    return (float(np.mean(angles)) if angles else float("nan")), xc, zs, fits


def _pour(count, seed, t_end, dt=2.5e-5):
    s = build_system(_cfg(repose_config(count, seed, dt)), with_ledger=False)
    s.run(int(round(t_end / dt)))
    return s


@register("repose", "granular dam break of three-sphere clumps: angle of repose, deterministic for a seed", issue=6)
def repose(level, out_dir: Path, comm) -> list:
    count, t_end = (150, 1.2) if level == "quick" else (600, 2.0)
    t0 = time.perf_counter()
    s = _pour(count, 7, t_end)
    wall = time.perf_counter() - t0
    st = s.state
    ang, xc, zs, fits = heap_angle(st.sph_pos, st.sph_radius)
    vmax = float(np.abs(st.vel).max())
    # determinism: the same seed again (short run) must give identical positions, bit for bit
    a = _pour(count, 7, 0.05)
    b = _pour(count, 7, 0.05)
    diff = float(np.abs(a.state.pos - b.state.pos).max())
    metrics = [in_interval("repose_angle", ang, 10.0, 60.0, unit="deg"),
               at_most("repeat_max_position_difference", diff, 0.0, unit="m"),
               report_only("max_speed_at_end", vmax, unit="m/s", note="heap at rest if ≪ 0.01"),
               report_only("wall_time", wall, unit="s", note=f"{count} clumps, {st.ns} spheres, {t_end} s")]

    def draw(fig):
        ax = fig.add_subplot(1, 1, 1)
        ax.scatter(st.sph_pos[:, 0], st.sph_pos[:, 2], s=3, c=st.sph_block % 7, cmap="tab10")
        ax.step(xc, zs, where="mid", color="k", lw=0.8, label="surface (top of highest sphere)")
        for f in fits:
            xx = np.linspace(xc.min(), xc.max(), 10)
            zz = np.polyval(f, xx)
            ok = (zz > 0) & (zz < zs.max())
            ax.plot(xx[ok], zz[ok], "r--", lw=1)
        ax.plot([], [], "r--", label=f"fits: angle of repose {ang:.1f}°")
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        ax.legend(fontsize=8)
        ax.set_title(f"{count} clumps, seed 7, t = {t_end} s")
    save_figure(out_dir, "repose.png", comm, draw)
    return metrics
