"""Pressure on the parts of a body's surface that the fluid does not reach
(``coupling.hidden_pressure``; 2D fluids).

Where a block lies on the floor, on a stopper or on another block, the gap fill
(fcm/levelset.py) makes the thin gap between them solid: the fluid's cut surface runs
around the fill, and the block's own surface inside it carries no pressure. A block lying
on the floor in still water then gets the water's weight on its top and nothing from
below — a downward load instead of Archimedes' lift (block_overturn's quick level: −13 N
on a 10.3 N block lying on its side, docs/coupling.md, session 29). Real contacts are rough
and their water connects to the water around them; the pressure in the gap goes from one
mouth's to the other's, as the uplift in a joint of masonry or a crack of a dam.

In a 2D fluid the surface of a body is a closed curve, sampled at the midpoints of segments
no longer than ``spacing``. The *fillness* f = (plain level set) − (the cut's level set) is
> 0 where the fill or a neighbour lowers the level set (P1, zero elsewhere, and zero where a
vent removed the fill). A sample is *hidden* where f > ``eps``, where it lies deeper than
``tol`` in the cut's solid, outside the mesh, or in a cut cell whose load goes to another
body. Each hidden run of samples gets the piezometric pressure p − ρ g·x and the density
interpolated linearly in arc length between its two *mouths*, the wetted samples next to it
on either side (P1 fields there), so water at rest gets its hydrostatic pressure on any path
round a corner. The load −Σ p n ds (× ``coupling.depth``) goes to the body only: its reaction
is the floor's or the other body's, and the fluid's momentum does not contain it. The part of
Γ where f > ``eps`` is the fill's own surface; the pressure part of the cut load there loads
the fill's water, not the body, and the coupling takes it off the body
(``CutDomain.pressure_load``). The exchange check compares the fluid's own load. A body whose
whole surface is hidden gets none (no mouth to take a pressure from; counted in ``unreached``).

For a convex body alone the P1 interpolant of its (convex) signed distance lies above zero
on its surface, so without a fill or a neighbour no sample is hidden.
"""
from __future__ import annotations

import numpy as np
from dolfinx import geometry
from mpi4py import MPI

from .levelset import BOX, CYLINDER, SPHERE, Shapes

#: ``cut_owner`` of a cell that Γ does not cut (any body's sample in it may be wetted)
NOT_CUT = -9


def perimeter_samples(kind: int, half: np.ndarray, offset: np.ndarray, rot: np.ndarray,
                      spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Section z = 0 of one primitive in its body frame, counter-clockwise: segment midpoints
    (n, 2) [m], outward unit normals (n, 2) and segment lengths (n,) [m], every segment
    ≤ ``spacing``. Box: the rectangle of its x, y half extents (its z axis must be the body
    z axis); sphere, or a cylinder along z: the circle of its radius."""
    if kind == BOX:
        if abs(abs(rot[2, 2]) - 1.0) > 1e-12:
            raise ValueError("a box tilted out of the plane has no rectangular section at z = 0")
        e1, e2 = rot[:2, 0], rot[:2, 1]
        if e1[0] * e2[1] - e1[1] * e2[0] < 0:           # keep the corners counter-clockwise
            e2 = -e2
        hx, hy = half[0], half[1]
        corners = [offset[:2] + sx * hx * e1 + sy * hy * e2 for sx, sy in ((1, -1), (1, 1), (-1, 1), (-1, -1))]
        normals = [e1, e2, -e1, -e2]
        pts, nrm, lens = [], [], []
        for k in range(4):
            a, b = corners[k], corners[(k + 1) % 4]
            length = float(np.linalg.norm(b - a))
            m = max(1, int(np.ceil(length / spacing)))
            s = (np.arange(m) + 0.5) / m
            pts.append(a[None, :] + s[:, None] * (b - a)[None, :])
            nrm.append(np.repeat(normals[k][None, :], m, axis=0))
            lens.append(np.full(m, length / m))
        return np.concatenate(pts), np.concatenate(nrm), np.concatenate(lens)
    if kind == SPHERE or (kind == CYLINDER and abs(abs(rot[2, 2]) - 1.0) <= 1e-12):
        r = half[0]
        m = max(8, int(np.ceil(2 * np.pi * r / spacing)))
        a = 2 * np.pi * (np.arange(m) + 0.5) / m
        n = np.column_stack([np.cos(a), np.sin(a)])
        return offset[:2] + r * n, n, np.full(m, 2 * np.pi * r / m)
    raise ValueError(f"primitive kind {kind}: no section at z = 0 that this module samples")


def interpolate_hidden(hidden: np.ndarray, values: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``values`` (n,) or (n, k) at every sample of one closed curve (cyclic order): wetted
    samples keep theirs, each hidden run gets the value linear in arc length between its two
    mouths (the wetted samples before and after it). All hidden: NaN everywhere."""
    n = len(hidden)
    out = np.array(values, dtype=float, copy=True)
    wet = np.flatnonzero(~hidden)
    if wet.size == 0:
        return np.full_like(out, np.nan)
    if wet.size == n:
        return out
    s = np.cumsum(lengths) - 0.5 * lengths            # arc position of each midpoint
    total = float(lengths.sum())
    for i in np.flatnonzero(hidden):
        k = np.searchsorted(wet, i)                    # the mouths: wet[k - 1] before, wet[k] after (cyclic)
        a, b = wet[k - 1], wet[k % wet.size]
        sa = s[a] if a < i else s[a] - total
        sb = s[b] if b > i else s[b] + total
        out[i] = out[a] + (out[b] - out[a]) * (s[i] - sa) / (sb - sa)
    return out


def hidden_pressure(hidden: np.ndarray, p: np.ndarray, rho: np.ndarray, gx: np.ndarray,
                    lengths: np.ndarray) -> np.ndarray:
    """Pressure [Pa] on one closed curve: wetted samples keep ``p``; on each hidden run the
    piezometric pressure p − ρ g·x and the density ρ are interpolated between its mouths
    (:func:`interpolate_hidden`) and p = (p − ρ g·x) + ρ g·x at the sample (``gx`` = g·x
    [m²/s²] per sample). Exact for water at rest whatever the run's path."""
    both = interpolate_hidden(hidden, np.column_stack([p - rho * gx, rho]), lengths)
    return both[:, 0] + both[:, 1] * gx


class HiddenSurface:
    """The samples of every moving body's surface and the load of :func:`interpolate_hidden`
    on its hidden runs (2D). ``level`` and ``pressure`` are P1 functions on ``mesh``."""

    def __init__(self, mesh, shapes: Shapes, nbodies: int, moving: np.ndarray, spacing: float) -> None:
        if mesh.geometry.dim != 2:
            raise ValueError("hidden-surface pressure is implemented for 2D fluids only")
        self.mesh, self.comm, self.nb = mesh, mesh.comm, int(nbodies)
        self.tdim = mesh.topology.dim
        self.tree = geometry.BoundingBoxTree(mesh, self.tdim)
        self.n_owned = mesh.topology.index_map(self.tdim).size_local
        self.bodies = []                    # (body, local points, normals, lengths)
        for b in np.flatnonzero(np.asarray(moving, bool)):
            mine = np.flatnonzero(shapes.body == b)
            if mine.size != 1:
                raise ValueError(f"block {b} is made of {mine.size} level-set primitives; the hidden-surface "
                                 "pressure needs one (a box block, a structure block or a one-sphere block)")
            k = mine[0]
            self.bodies.append((int(b),) + perimeter_samples(int(shapes.kind[k]), shapes.half[k],
                                                               shapes.offset[k], shapes.rot[k], spacing))
        self.hidden_length = np.zeros(self.nb)       # [m] per body, last call
        self.unreached = 0                           # bodies with every sample hidden, last call

    def _values(self, functions, points: np.ndarray, body: np.ndarray,
                cut_owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(len(functions), n) values at ``points`` (n, 3) on every rank, NaN outside the
        mesh, and per point whether a cell containing it is cut and gives its load to others
        than the point's ``body`` (``cut_owner`` (owned cells, 2): owner and second owner of
        each cut cell's load, NOT_CUT for the cells Γ does not cut)."""
        cands = geometry.compute_collisions(self.tree, points)
        cells = geometry.compute_colliding_cells(self.mesh, cands, points)
        local = np.zeros((len(functions), len(points)))
        count = np.zeros(len(points))
        flag = np.zeros(len(points))
        found, first = [], []
        for i in range(len(points)):
            links = cells.links(i)
            links = links[links < self.n_owned]
            if len(links):
                found.append(i)
                first.append(links[0])
                foreign = (cut_owner[links, 0] != NOT_CUT) & (cut_owner[links, 0] != body[i]) \
                    & (cut_owner[links, 1] != body[i])
                flag[i] = float(foreign.any())            # any cell: the same on any partition
        if found:
            found = np.asarray(found)
            count[found] = 1.0
            for j, fn in enumerate(functions):
                local[j, found] = fn.eval(points[found], np.asarray(first, np.int32))[:, 0]
        local = self.comm.allreduce(local, op=MPI.SUM)
        count = self.comm.allreduce(count, op=MPI.SUM)
        flag = self.comm.allreduce(flag, op=MPI.SUM)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(count > 0, local / np.maximum(count, 1.0), np.nan), flag > 0

    def load(self, level, fillness, pressure, density, gravity: np.ndarray, cut_owner: np.ndarray,
             pos: np.ndarray, rot: np.ndarray, depth: float, tol: float, eps: float) -> tuple[np.ndarray, np.ndarray]:
        """Force (nb, 3) [N] and torque about each body's centre (nb, 3) [N m] of
        :func:`hidden_pressure` on the hidden samples: those where the P1 ``fillness`` (plain
        level set − the mesh's, > 0 where the fill or a neighbour sets it) exceeds ``eps`` [m],
        the P1 ``level`` is below −``tol`` [m], outside the mesh, or in a cut cell whose load
        goes to another body (``cut_owner``, :meth:`_values`). ``density`` is a P1 function
        [kg/m³] or a number, ``gravity`` (2,) [m/s²]. Collective; same on all ranks."""
        force, torque = np.zeros((self.nb, 3)), np.zeros((self.nb, 3))
        self.hidden_length[:] = 0.0
        self.unreached = 0
        self.last = {}                               # per body with hidden samples: the samples, for plots
        if not self.bodies:
            return force, torque
        world = []
        for b, x, n, ds in self.bodies:
            R = rot[b, :2, :2]
            world.append((pos[b, :2] + x @ R.T, n @ R.T))
        pts = np.zeros((sum(len(w[0]) for w in world), 3))
        pts[:, :2] = np.concatenate([w[0] for w in world])
        fns = (level, fillness, pressure) if np.isscalar(density) else (level, fillness, pressure, density)
        body = np.concatenate([np.full(len(x), b) for b, x, _, _ in self.bodies])
        vals, foreign = self._values(fns, pts, body, cut_owner)
        rho_all = np.full(len(pts), float(density)) if np.isscalar(density) else vals[3]
        start = 0
        for (b, _, _, ds), (xw, nw) in zip(self.bodies, world):
            sl = slice(start, start + len(ds))
            start += len(ds)
            # NaN (outside the mesh) counts as hidden
            hidden = ~(vals[0, sl] >= -tol) | ~(vals[1, sl] <= eps) | foreign[sl]
            if not hidden.any():
                continue
            ph = hidden_pressure(hidden, np.nan_to_num(vals[2, sl]), np.nan_to_num(rho_all[sl]),
                                 xw @ np.asarray(gravity, float)[:2], ds)
            if not np.isfinite(ph).all():
                self.unreached += 1
                continue
            self.last[b] = {"x": xw, "n": nw, "ds": ds, "hidden": hidden, "p": vals[2, sl], "p_hidden": ph}
            f = -(ph[hidden] * ds[hidden])[:, None] * nw[hidden] * depth      # −p n ds per sample
            r = xw[hidden] - pos[b, None, :2]
            force[b, :2] = f.sum(axis=0)
            torque[b, 2] = float((r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]).sum())
            self.hidden_length[b] = float(ds[hidden].sum())
        return force, torque
