"""Contact, paper eqs 18–20: linear spring + dashpot (normal and tangential) + Coulomb slider.

For a contact with overlap δ > 0, unit normal n (from sphere i towards the other body),
relative velocity of the contact point v = v_i − v_other, v_n = v·n (> 0 approaching),
v_t = v − v_n n, and tangential spring history u_t (rotated onto the current tangent
plane every step, magnitude kept, then u_t += v_t Δt)::

    F_N   = k δ + c v_n                (eq 18; clipped to F_N ≥ 0 when clip_normal)
    f_t   = −k_t u_t − c_t v_t          (eq 19)
    |f_t| > μ F_N  →  f_t = μ F_N f_t/|f_t|,  u_t = −f_t / k_t   (slider; no dashpot)
    force on i = −F_N n + f_t,  on the other body the opposite, applied at the contact
    point x_c (midway through the overlap); torques about each block's centre of mass.

Dashpots from the restitution coefficient e (eq 20, tutorial §5):
c = 2 h √(m* k), h = −ln e / √(ln² e + π²), with m* = m_i m_j/(m_i + m_j) of the two
*blocks* (the block mass when the other body is a wall or a fixed block).

Normal force at the end of contact — clipping: with ``clip_normal`` (the default) the
normal force never turns attractive, F_N = max(kδ + c v_n, 0). Then the contact ends
when F_N reaches 0 (before δ = 0) and the sphere leaves with a *higher* restitution than
eq 20's e (e = 0.5 → 0.55; see ``restitution_clipped``). Without clipping eq 20 is
exact for the linear model. Mixing of two materials: k = 2 k_1 k_2/(k_1 + k_2),
k_t likewise, h = (h_1 + h_2)/2, μ = min(μ_1, μ_2).

Onset/release correction of the normal spring (energy-consistent across δ = 0): the
leapfrog's work of the spring force values F_n over the steps is Σ_n F_n (δ_{n+1} − δ_{n−1})/2,
i.e. the trapezoid rule on each step, exact for the linear spring and in flight but not on
the step [n−1, n] in which δ changes sign: there it misses the exact ½kδ² by
k·D with D = ½ δ_{n−1} δ_n (onset, δ_{n−1} < 0 < δ_n) or −½ δ_{n−1} δ_n (release), an
O((ωΔt)²) energy error of random sign per impact. It is cancelled by one corrected spring
force k(δ + ε) at one step next to the crossing, ε = 2D/(δ_{m+1} − δ_{m−1}), the denominator
(≈ 2 v_n Δt, well conditioned) predicted as 2δ_m − δ_{m−1} − Δt² F_N/m* + a_other, where
a_other = δ_m − (that prediction made at step m−1) carries the other forces (gravity, other
contacts) with a lag of one step:

- onset: deferred to the second step of the contact (m = n + 1), so that a_other is known;
  δ_{n−1} = δ_n − v_n Δt (v_n the normal relative velocity of the step), the force is
  reduced (ε < 0, δ + ε clamped ≥ 0);
- release: at the first step out of contact (m = n), with δ_{n−1} kept per contact: a
  small *attractive* normal force kε (ε < 0, never clipped, applied once) that takes back
  the part of the last spring impulse that fell after δ = 0. Only when the last normal
  force was > 0 (a contact that ended clipped has no kink to correct).

Both apply only while the overlap keeps moving the same way (growing, shrinking); the
spring energy stays ½kδ² and the dashpot force is unchanged (F_N = k(δ + ε) + c v_n, dashpot
part F_N − k(δ + ε)). Cost O(1) per contact, history slots 7–10.

Ledger: stored energy ½kδ² + ½k_t|u_t|²; dashpot and slider losses are the work of those
forces over each step by the trapezoid rule, Δt v_{n−1/2}·(F_{n−1} + F_n)/2 — the same
quadrature that makes the leapfrog kinetic energy ½ m v_{n−1/2}·v_{n+1/2} exact — so what the
balance shows is the integration error of the springs (contact opening/closing, rotation).
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from . import L_DASHPOT, L_FRICTION, L_SPRING
from .neighbours import NeighbourList, carry_history

HIST = 11  # per-contact history: tangential spring u_t (3), last normal dashpot force, last tangential dashpot
#            force (3), then for the onset/release correction: last overlap δ_n (> 0 while in contact),
#            deferred onset deficit (m²), self-predicted overlap for this step, last normal force F_N


@nb.njit(cache=True, inline="always")
def _onset_release_eps(Dk, delta, dprev, un_grow, aoth, k, c, un, mstar, clip, dt, release):
    """Overlap correction ε (m) of this step's spring force k(δ + ε) such that the trapezoidal
    work of the step's force over the two adjacent steps, ½ kε (δ_{n+1} − δ_{n−1}), equals
    k·Dk (the deficit of the kink at δ = 0). δ_{n+1} is predicted as
    2δ_n − δ_{n−1} − Δt² F_N/m* + a_other, a_other the last step's prediction miss.
    Applied only while the overlap keeps moving the same way (growing at an onset,
    shrinking at a release); 0 otherwise."""
    w = dt * dt / mstar
    eps = 0.0
    for _ in range(3):
        if release:
            FN = k * eps
        else:
            FN = k * (delta + eps) + c * un
            if clip and FN < 0.0:
                FN = 0.0
        den = 2.0 * delta - 2.0 * dprev - w * FN + aoth
        if (not release and den > un_grow) or (release and den < un_grow):
            eps = 2.0 * Dk / den
        else:
            return 0.0
    return eps


@nb.njit(cache=True, inline="always")
def _law(delta, nx, ny, nz, ux, uy, uz, hist, k, kt, c, ct, mu, clip, dt, mstar):
    """Eqs 18–19 for one contact. (ux, uy, uz) is the relative velocity of the leapfrog half
    step n−1/2, i.e. the relative displacement of the step n−1 → n over Δt; the dashpots use
    it too (the tutorial's c(u_n − u_{n−1})/Δt, whose stability limit is Δt_cr). Returns (fx, fy, fz, e_spring, d_dash,
    d_fric) with f the force on side i; ``hist`` (HIST,) is updated in place.

    Dashpot loss uses the trapezoid of the dashpot force over the step, Δt v_{n−1/2}·(F_{n−1} +
    F_n)/2, which is the work that matches the leapfrog kinetic energy ½ m v_{n−1/2}·v_{n+1/2}."""
    un = ux * nx + uy * ny + uz * nz
    sx = ux - un * nx
    sy = uy - un * ny
    sz = uz - un * nz
    vn, tx, ty, tz = un, sx, sy, sz
    # onset/release correction of the spring force (module docstring): k δ → k (δ + ε)
    dprev = hist[7]
    if dprev > 0.0:                      # in contact at the previous step
        Dk = hist[8]                     # deferred onset deficit
        aoth = delta - hist[9]           # last step's prediction miss (gravity, other contacts)
    else:                                # first step of the contact
        Dk = 0.0
        aoth = 0.0
        dprev = delta - un * dt          # overlap at the previous step (< 0 at a true onset)
    eps = 0.0
    if Dk != 0.0:
        eps = _onset_release_eps(Dk, delta, dprev, delta - dprev, aoth, k, c, vn, mstar, clip, dt, False)
        if delta + eps < 0.0:
            eps = -delta
    deff = delta + eps
    FN = k * deff + c * vn
    if clip and FN < 0.0:
        FN = 0.0
    fdn = FN - k * deff
    hist[8] = 0.5 * dprev * delta if (hist[7] <= 0.0 and dprev < 0.0) else 0.0
    hist[9] = 2.0 * delta - dprev - dt * dt * FN / mstar     # δ_{n+1} from this contact alone
    hist[7] = delta
    hist[10] = FN
    d_dash = 0.5 * (fdn + hist[3]) * un * dt
    hist[3] = fdn
    # rotate the history onto the current tangent plane, keeping its magnitude
    hx, hy, hz = hist[0], hist[1], hist[2]
    h2 = hx * hx + hy * hy + hz * hz
    if h2 > 0.0:
        hn = hx * nx + hy * ny + hz * nz
        hx -= hn * nx
        hy -= hn * ny
        hz -= hn * nz
        p2 = hx * hx + hy * hy + hz * hz
        if p2 > 0.0:
            s = math.sqrt(h2 / p2)
            hx *= s
            hy *= s
            hz *= s
    ox, oy, oz = hx, hy, hz      # u_{n−1} on the current tangent plane
    hx += sx * dt
    hy += sy * dt
    hz += sz * dt
    fx = -kt * hx - ct * tx
    fy = -kt * hy - ct * ty
    fz = -kt * hz - ct * tz
    ft = math.sqrt(fx * fx + fy * fy + fz * fz)
    fmax = mu * FN
    d_fric = 0.0
    gx = gy = gz = 0.0          # tangential dashpot force applied this step
    if ft > fmax:
        if ft > 0.0:
            s = fmax / ft
            fx *= s
            fy *= s
            fz *= s
        nhx = -fx / kt
        nhy = -fy / kt
        nhz = -fz / kt
        # slider work over the step with the trapezoid rule (the quadrature of the ledger's
        # kinetic energy): ½ k_t (u_trial − u_n)·(u_{n−1} + u_n)
        d_fric = 0.5 * kt * ((hx - nhx) * (ox + nhx) + (hy - nhy) * (oy + nhy) + (hz - nhz) * (oz + nhz))
        hx, hy, hz = nhx, nhy, nhz
    else:
        gx = -ct * tx
        gy = -ct * ty
        gz = -ct * tz
    d_dash -= 0.5 * ((gx + hist[4]) * sx + (gy + hist[5]) * sy + (gz + hist[6]) * sz) * dt
    hist[0] = hx
    hist[1] = hy
    hist[2] = hz
    hist[4] = gx
    hist[5] = gy
    hist[6] = gz
    e_spring = 0.5 * k * delta * delta + 0.5 * kt * (hx * hx + hy * hy + hz * hz)
    return -FN * nx + fx, -FN * ny + fy, -FN * nz + fz, e_spring, d_dash, d_fric


@nb.njit(cache=True, inline="always")
def _pointvel(vel, omega, b, rx, ry, rz):
    """Velocity of the material point at offset r from the centre of mass of block b."""
    return (vel[b, 0] + omega[b, 1] * rz - omega[b, 2] * ry,
            vel[b, 1] + omega[b, 2] * rx - omega[b, 0] * rz,
            vel[b, 2] + omega[b, 0] * ry - omega[b, 1] * rx)


@nb.njit(cache=True, inline="always")
def _add_load(force, torque, b, fx, fy, fz, rx, ry, rz):
    """Add the force (fx, fy, fz) acting at arm r = (rx, ry, rz) from block b's centre."""
    force[b, 0] += fx
    force[b, 1] += fy
    force[b, 2] += fz
    torque[b, 0] += ry * fz - rz * fy
    torque[b, 1] += rz * fx - rx * fz
    torque[b, 2] += rx * fy - ry * fx


@nb.njit(cache=True, inline="always")
def _release(delta, nx, ny, nz, vx, vy, vz, hist, k, mstar, dt):
    """Contact lost this step: the last half of the trapezoid of the dashpot work, the
    release correction of the spring (normal force k ε, ε ≤ 0, unclipped: it takes back the
    part of the last step's spring impulse that fell after δ = 0; only when the last normal
    force was > 0), then reset. Returns (dashpot loss, F_N)."""
    d = 0.0
    vn = vx * nx + vy * ny + vz * nz
    if hist[3] != 0.0 or hist[4] != 0.0 or hist[5] != 0.0 or hist[6] != 0.0:
        d = 0.5 * hist[3] * vn * dt - 0.5 * (hist[4] * (vx - vn * nx) + hist[5] * (vy - vn * ny)
                                             + hist[6] * (vz - vn * nz)) * dt
    FN = 0.0
    p = hist[7]
    if p > 0.0 and hist[10] > 0.0:
        Dk = hist[8] - 0.5 * p * delta
        FN = k * _onset_release_eps(Dk, delta, p, delta - p, delta - hist[9], k, 0.0, vn, mstar, False, dt, True)
    for q in range(hist.shape[0]):
        hist[q] = 0.0
    return d, FN


@nb.njit(cache=True, inline="always")
def _mix(mat_k, mat_kt, mat_h, mat_mu, a, b):
    k = 2.0 * mat_k[a] * mat_k[b] / (mat_k[a] + mat_k[b])
    kt = 2.0 * mat_kt[a] * mat_kt[b] / (mat_kt[a] + mat_kt[b])
    return k, kt, 0.5 * (mat_h[a] + mat_h[b]), min(mat_mu[a], mat_mu[b])


@nb.njit(cache=True)
def material_table(mat_k, mat_kt, mat_h, mat_mu):
    """(nmat, nmat, 4) table of the mixed (k, k_t, h, μ) of every material pair (:func:`_mix`)."""
    nm = mat_k.shape[0]
    tab = np.empty((nm, nm, 4))
    for a in range(nm):
        for b in range(nm):
            k, kt, h, mu = _mix(mat_k, mat_kt, mat_h, mat_mu, a, b)
            tab[a, b, 0] = k
            tab[a, b, 1] = kt
            tab[a, b, 2] = h
            tab[a, b, 3] = mu
    return tab


@nb.njit(cache=True)
def history_held(hist):
    """1 where a history row (last axis) has a non-zero entry, else 0 (uint8)."""
    n = hist.shape[0]
    m = hist.shape[1]
    out = np.zeros(n, np.uint8)
    for p in range(n):
        for q in range(m):
            if hist[p, q] != 0.0:
                out[p] = 1
                break
    return out


@nb.njit(cache=True, inline="always")
def _pair_one(p, i, j, dx, dy, dz, dist, delta, hist, held, act, sph_pos, sph_radius, sph_block, sph_material,
              pos, vel, omega, mass, fixed, tab, clip, dt, pair_f, pair_x):
    """Pair p = (i, j) in contact (delta > 0) or with a history to release or reset
    (see :func:`pair_forces`). Returns (spring energy, dashpot loss, slider loss, 1 if in
    contact else 0)."""
    if dist == 0.0:
        act[p] = 0
        return 0.0, 0.0, 0.0, 0
    if delta <= 0.0 and hist[p, 3] == 0.0 and hist[p, 4] == 0.0 and hist[p, 5] == 0.0 and hist[p, 6] == 0.0 \
            and hist[p, 7] <= 0.0:
        # out of contact and nothing to release
        for q in range(hist.shape[1]):
            if hist[p, q] != 0.0:
                hist[p, q] = 0.0
        held[p] = 0
        act[p] = 0
        return 0.0, 0.0, 0.0, 0
    nx = dx / dist
    ny = dy / dist
    nz = dz / dist
    a = sph_radius[i] - 0.5 * delta
    cx = sph_pos[i, 0] + a * nx
    cy = sph_pos[i, 1] + a * ny
    cz = sph_pos[i, 2] + a * nz
    bi = sph_block[i]
    bj = sph_block[j]
    rix = cx - pos[bi, 0]
    riy = cy - pos[bi, 1]
    riz = cz - pos[bi, 2]
    rjx = cx - pos[bj, 0]
    rjy = cy - pos[bj, 1]
    rjz = cz - pos[bj, 2]
    ai = _pointvel(vel, omega, bi, rix, riy, riz)
    aj = _pointvel(vel, omega, bj, rjx, rjy, rjz)
    ux, uy, uz = ai[0] - aj[0], ai[1] - aj[1], ai[2] - aj[2]
    if fixed[bi]:
        mstar = mass[bj]
    elif fixed[bj]:
        mstar = mass[bi]
    else:
        mstar = mass[bi] * mass[bj] / (mass[bi] + mass[bj])
    ma = sph_material[i]
    mb = sph_material[j]
    k = tab[ma, mb, 0]
    kt = tab[ma, mb, 1]
    h = tab[ma, mb, 2]
    mu = tab[ma, mb, 3]
    act[p] = 1
    if delta <= 0.0:
        dd, FN = _release(delta, nx, ny, nz, ux, uy, uz, hist[p], k, mstar, dt)
        held[p] = 0
        if FN == 0.0:
            act[p] = 0
        pair_f[p, 0] = -FN * nx
        pair_f[p, 1] = -FN * ny
        pair_f[p, 2] = -FN * nz
        pair_x[p, 0] = cx
        pair_x[p, 1] = cy
        pair_x[p, 2] = cz
        return 0.0, dd, 0.0, 0
    c = 2.0 * h * math.sqrt(mstar * k)
    ct = 2.0 * h * math.sqrt(mstar * kt)
    fx, fy, fz, es, dd, df = _law(delta, nx, ny, nz, ux, uy, uz, hist[p], k, kt, c, ct, mu, clip, dt, mstar)
    held[p] = 1
    pair_f[p, 0] = fx
    pair_f[p, 1] = fy
    pair_f[p, 2] = fz
    pair_x[p, 0] = cx
    pair_x[p, 1] = cy
    pair_x[p, 2] = cz
    return es, dd, df, 1


@nb.njit(cache=True, parallel=True)
def pair_forces(pairs, hist, held, act, sph_pos, sph_radius, sph_block, sph_material, pos, vel, omega,
                mass, fixed, mat_k, mat_kt, mat_h, mat_mu, clip, dt, pair_f, pair_x):
    """Sphere–sphere contact over the Verlet pairs. Writes the force on sphere pairs[p,0]
    into pair_f[p] and the contact point into pair_x[p] and sets ``act[p]`` = 1 when the pair
    carries a force this step (``act[p]`` = 0: pair_f[p], pair_x[p] not written, nothing to
    gather); resets the history of pairs out of contact. ``held[p]`` (uint8) is 1 where
    hist[p] may be non-zero and 0 where it is all zero (kept up to date here): a pair out of
    contact with held 0 is skipped after the distance test without reading its history (the
    common case in a Verlet list). Returns (stored spring energy, dashpot loss, slider loss,
    n_contacts)."""
    e_s = 0.0
    d_d = 0.0
    d_f = 0.0
    ncon = 0
    tab = material_table(mat_k, mat_kt, mat_h, mat_mu)
    for p in nb.prange(pairs.shape[0]):
        i = pairs[p, 0]
        j = pairs[p, 1]
        dx = sph_pos[j, 0] - sph_pos[i, 0]
        dy = sph_pos[j, 1] - sph_pos[i, 1]
        dz = sph_pos[j, 2] - sph_pos[i, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        delta = sph_radius[i] + sph_radius[j] - dist
        if delta <= 0.0 and held[p] == 0:
            act[p] = 0                   # out of contact, history all zero: nothing to do
            continue
        es, dd, df, c = _pair_one(p, i, j, dx, dy, dz, dist, delta, hist, held, act, sph_pos, sph_radius, sph_block,
                                  sph_material, pos, vel, omega, mass, fixed, tab, clip, dt, pair_f, pair_x)
        e_s += es
        d_d += dd
        d_f += df
        ncon += c
    return e_s, d_d, d_f, ncon


@nb.njit(cache=True, inline="always")
def _gather_block(b, blk_sph_start, pos, sp_start, sp_pair, sp_sign, act, pair_f, pair_x, force, torque):
    """force[b] += Σ ±pair_f over the pairs of b's spheres with act[p] = 1, in CSR order;
    torque about pos[b] likewise."""
    fx = fy = fz = tx = ty = tz = 0.0
    for s in range(blk_sph_start[b], blk_sph_start[b + 1]):
        for k in range(sp_start[s], sp_start[s + 1]):
            p = sp_pair[k]
            if act[p] == 0:
                continue
            sg = sp_sign[k]
            gx = sg * pair_f[p, 0]
            gy = sg * pair_f[p, 1]
            gz = sg * pair_f[p, 2]
            if gx == 0.0 and gy == 0.0 and gz == 0.0:
                continue
            rx = pair_x[p, 0] - pos[b, 0]
            ry = pair_x[p, 1] - pos[b, 1]
            rz = pair_x[p, 2] - pos[b, 2]
            fx += gx
            fy += gy
            fz += gz
            tx += ry * gz - rz * gy
            ty += rz * gx - rx * gz
            tz += rx * gy - ry * gx
    force[b, 0] += fx
    force[b, 1] += fy
    force[b, 2] += fz
    torque[b, 0] += tx
    torque[b, 1] += ty
    torque[b, 2] += tz


@nb.njit(cache=True, parallel=True)
def gather_pair_forces(blk_sph_start, pos, sp_start, sp_pair, sp_sign, act, pair_f, pair_x, force, torque):
    """force[b] += Σ ±pair_f over the pairs of b's spheres with act[p] = 1; torque about pos[b]
    likewise (a fixed order per block: the result does not depend on the thread count)."""
    for b in nb.prange(pos.shape[0]):
        _gather_block(b, blk_sph_start, pos, sp_start, sp_pair, sp_sign, act, pair_f, pair_x, force, torque)


class Materials:
    """Per-material arrays for the kernels: k [N/m], k_t [N/m], h [-], μ [-]."""

    def __init__(self, k, kt, h, mu):
        self.k = np.asarray(k, np.float64)
        self.kt = np.asarray(kt, np.float64)
        self.h = np.asarray(h, np.float64)
        self.mu = np.asarray(mu, np.float64)


class SphereContact:
    """Interaction: sphere–sphere contact between different blocks over a Verlet list."""

    name = "contact"

    def __init__(self, materials: Materials, skin: float, clip_normal: bool = True):
        self.mat = materials
        self.clip = bool(clip_normal)
        self.neighbours = NeighbourList(skin)
        self.hist = np.zeros((0, HIST))
        self.held = np.zeros(0, np.uint8)     # 1 where hist[p] may be non-zero
        self.act = np.zeros(0, np.uint8)      # 1 where pair_f[p] is this step's force
        self.pair_f = np.zeros((0, 3))
        self.pair_x = np.zeros((0, 3))
        self.n_contacts = 0

    def pair_stage(self, state, dt):
        """Verlet check (rebuild and history carry-over when needed) and the pair kernel:
        fills pair_f, pair_x, act. Returns (spring energy, dashpot loss, slider loss)."""
        nl = self.neighbours
        if nl.needs_rebuild(state.sph_pos):
            old = nl.rebuild(state.sph_pos, state.sph_radius, state.sph_block)
            self.hist = carry_history(old, self.hist, nl.pairs, state.ns)
            self._new_buffers()
        if len(nl.pairs) == 0:
            self.n_contacts = 0
            return 0.0, 0.0, 0.0
        m = self.mat
        es, dd, df, nc = pair_forces(nl.pairs, self.hist, self.held, self.act, state.sph_pos, state.sph_radius,
                                     state.sph_block, state.sph_material, state.pos, state.vel, state.omega,
                                     state.mass, state.fixed, m.k, m.kt, m.h, m.mu, self.clip, dt,
                                     self.pair_f, self.pair_x)
        self.n_contacts = nc
        return es, dd, df

    def add_forces(self, state, force, torque, ledger, dt):
        nl = self.neighbours
        es, dd, df = self.pair_stage(state, dt)
        if len(nl.pairs) == 0:
            return
        gather_pair_forces(state.blk_sph_start, state.pos, nl.sp_start, nl.sp_pair, nl.sp_sign, self.act,
                           self.pair_f, self.pair_x, force, torque)
        ledger[L_SPRING] += es
        ledger[L_DASHPOT] += dd
        ledger[L_FRICTION] += df

    def _new_buffers(self):
        n = len(self.neighbours.pairs)
        self.held = history_held(self.hist)
        self.act = np.zeros(n, np.uint8)
        self.pair_f = np.zeros((n, 3))
        self.pair_x = np.zeros((n, 3))

    def stiffness_bound(self):
        return float(self.mat.k.max()), float(self.mat.h.max())

    def checkpoint_arrays(self):
        nl = self.neighbours
        ref = nl.ref_pos if nl.ref_pos is not None else np.zeros((0, 3))
        return {"pairs": nl.pairs, "hist": self.hist, "ref_pos": ref}

    def restore(self, arrays):
        nl = self.neighbours
        nl.pairs = np.asarray(arrays["pairs"], np.int64).reshape(-1, 2)
        self.hist = np.asarray(arrays["hist"], np.float64).reshape(-1, HIST)
        ref = np.asarray(arrays["ref_pos"], np.float64).reshape(-1, 3)
        nl.ref_pos = ref if len(ref) else None
        from .neighbours import sphere_pair_map
        ns = len(ref) if len(ref) else int(nl.pairs.max() + 1 if len(nl.pairs) else 0)
        nl.sp_start, nl.sp_pair, nl.sp_sign = sphere_pair_map(nl.pairs, ns)
        self._new_buffers()
