"""Rigid blocks: mass properties, surface spheres, quaternion constructors (SPEC §2, eqs 21–27).

A block's mass, centre of mass and inertia come either from its *solid shape* and density
(the spheres only sit on its surface, paper §3) or, for a pure clump, from its spheres
(overlaps are not subtracted: mass = Σ 4/3 π r³ ρ; say so when it matters). The body
frame is the principal frame: ``sph_local`` is expressed in it, ``inertia`` is diagonal.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..geometry import rotate


@dataclass(frozen=True)
class BlockTemplate:
    """One block shape in its principal frame: mass [kg], principal inertia [kg m²],
    sphere offsets from the centre of mass [m] and radii [m], plus the rotation
    ``R_body`` (principal → the frame the shape was described in) and the centre of mass
    ``com`` [m] in that frame where it is not its origin (a block from a CAD file)."""

    mass: float
    inertia: np.ndarray
    sph_local: np.ndarray
    sph_radius: np.ndarray
    R_body: np.ndarray
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))


def box_template(size, density: float, radius: float, spacing: float | None = None) -> BlockTemplate:
    """Solid rectangular box ``size = (a, b, c)`` [m] of ``density`` [kg/m³].

    Mass and inertia are the solid box's: I = m/12 (b²+c², a²+c², a²+b²). Spheres of
    ``radius`` tile its surface with centres inset by ``radius`` so that the outer sphere
    surfaces lie on the box faces; ``spacing`` (default 2·radius) is the largest centre
    distance along an edge.
    """
    a, b, c = (float(s) for s in size)
    if min(a, b, c) < 2 * radius:
        raise ValueError(f"box {size} is thinner than one sphere diameter {2 * radius}")
    m = density * a * b * c
    inertia = m / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    spacing = 2.0 * radius if spacing is None else spacing
    axes = []
    for L in (a, b, c):
        half = L / 2 - radius
        n = max(int(np.ceil(2 * half / spacing)), 0) + 1
        axes.append(np.linspace(-half, half, n) if half > 0 else np.zeros(1))
    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    lim = np.array([a, b, c]) / 2 - radius
    on_surface = np.any(np.isclose(np.abs(pts), lim[None, :], rtol=0, atol=1e-12 * max(a, b, c)), axis=1)
    pts = pts[on_surface]
    return BlockTemplate(m, inertia, pts, np.full(len(pts), float(radius)), np.eye(3))


def clump_template(centres, radii, density: float) -> BlockTemplate:
    """Pure clump of spheres (centres [m] in any frame, radii [m]): mass = Σ 4/3 π r³ ρ,
    inertia Σ (2/5 m r² I + m(|d|² I − d dᵀ)) diagonalised; overlaps not subtracted."""
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(radii, dtype=np.float64).reshape(-1)
    ms = density * 4.0 / 3.0 * np.pi * r ** 3
    m = ms.sum()
    com = (ms[:, None] * c).sum(0) / m
    d = c - com
    J = np.zeros((3, 3))
    for mi, ri, di in zip(ms, r, d):
        J += 0.4 * mi * ri * ri * np.eye(3) + mi * (di @ di * np.eye(3) - np.outer(di, di))
    w, V = np.linalg.eigh(J)
    if np.linalg.det(V) < 0:
        V[:, 2] *= -1
    return BlockTemplate(m, w, d @ V, r.copy(), V)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a proper rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


def axis_angle_quat(axis, angle: float) -> np.ndarray:
    """Quaternion of a rotation by ``angle`` [rad] about ``axis``."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * a])


@nb.njit(cache=True, parallel=True)
def update_sphere_positions(pos, quat, sph_block, sph_local, sph_pos):
    """sph_pos[s] = pos[b] + R(q_b) sph_local[s] (kernel; reference: DEMState.update_spheres)."""
    for s in nb.prange(sph_block.shape[0]):
        b = sph_block[s]
        rx, ry, rz = rotate(quat[b, 0], quat[b, 1], quat[b, 2], quat[b, 3],
                            sph_local[s, 0], sph_local[s, 1], sph_local[s, 2])
        sph_pos[s, 0] = pos[b, 0] + rx
        sph_pos[s, 1] = pos[b, 1] + ry
        sph_pos[s, 2] = pos[b, 2] + rz


@nb.njit(cache=True, inline="always")
def _place_block_spheres(b, pos, quat, blk_sph_start, sph_local, sph_pos):
    """sph_pos[s] = pos[b] + R(q_b) sph_local[s] for the spheres of block b (as
    :func:`update_sphere_positions`)."""
    for s in range(blk_sph_start[b], blk_sph_start[b + 1]):
        rx, ry, rz = rotate(quat[b, 0], quat[b, 1], quat[b, 2], quat[b, 3],
                            sph_local[s, 0], sph_local[s, 1], sph_local[s, 2])
        sph_pos[s, 0] = pos[b, 0] + rx
        sph_pos[s, 1] = pos[b, 1] + ry
        sph_pos[s, 2] = pos[b, 2] + rz
