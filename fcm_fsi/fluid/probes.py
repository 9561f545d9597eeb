"""Fields at points on any number of ranks: probes, wave gauges and pressure sensors.

A point is evaluated in a cell that holds it (the finite-element interpolant there, as
``Function.eval``) by the lowest rank that owns such a cell; the others add zeros, so every
rank gets the same value, equal to a 1-rank run's. Moving points (sensors on blocks) keep
their cell while they stay strictly inside it (fcm/locate.PointLocator).

A gauge is a vertical line (along the last axis) from the bottom to the top of the mesh,
sampled at spacing ≤ ``h_min``/2: the liquid height is the bottom plus ∫φ dz by the
trapezoid rule over the samples (exact for the P1 φ up to the sampling of its kinks).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from ..fcm.locate import PointLocator


class PointValues:
    """Values of dolfinx Functions at ``npoints`` points (fixed or moving) of ``mesh``; collective."""

    def __init__(self, mesh, npoints: int) -> None:
        self.mesh, self.comm = mesh, mesh.comm
        self.gdim = mesh.geometry.dim
        self.locator = PointLocator(mesh, npoints)
        self.slots = np.arange(npoints)

    def cells(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(index, cell) of the points (n, gdim) this rank evaluates (each found point on the
        lowest rank owning a cell that holds it), and ``found`` (n,), the same on every rank."""
        pts = np.zeros((len(points), 3))
        pts[:, : points.shape[1]] = points
        point, cell = self.locator.locate(self.slots, pts)
        first = np.unique(point, return_index=True)[1]            # one cell per point on this rank
        point, cell = point[first], cell[first]
        claim = np.full(len(points), self.comm.size, np.int64)
        claim[point] = self.comm.rank
        self.comm.Allreduce(MPI.IN_PLACE, claim, op=MPI.MIN)
        mine = claim[point] == self.comm.rank
        self._pts = pts
        return point[mine], cell[mine], claim < self.comm.size

    def values(self, functions: list, points: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """Each function at ``points`` as an (n, components) array (NaN where no cell holds the
        point), and ``found`` (n,) bool; the same on every rank."""
        index, cell, found = self.cells(points)
        out = []
        for fn in functions:
            ncomp = fn.function_space.dofmap.index_map_bs
            local = np.zeros((len(points), ncomp))
            if len(index):
                local[index] = np.reshape(fn.eval(self._pts[index], cell.astype(np.int32)), (len(index), ncomp))
            self.comm.Allreduce(MPI.IN_PLACE, local, op=MPI.SUM)
            local[~found] = np.nan
            out.append(local)
        return out, found


def vertical_line(position: tuple[float, ...], bottom: float, top: float, spacing: float, gdim: int) -> np.ndarray:
    """Points (n, gdim) from ``bottom`` to ``top`` [m] along the last axis at ``position`` (the
    other coordinates), at most ``spacing`` [m] apart, both ends included."""
    n = max(int(np.ceil((top - bottom) / spacing)), 1) + 1
    pts = np.zeros((n, gdim))
    pts[:, : gdim - 1] = position
    pts[:, -1] = np.linspace(bottom, top, n)
    return pts


def liquid_height(z: np.ndarray, phi: np.ndarray, bottom: float) -> float:
    """The liquid surface elevation [m]: ``bottom`` + ∫φ dz over the samples at heights ``z``
    (ascending; trapezoid rule)."""
    return bottom + float(np.sum(0.5 * (phi[1:] + phi[:-1]) * np.diff(z)))
