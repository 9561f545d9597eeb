"""Dirichlet conditions of the Navier–Stokes solver from the ``fluid.boundaries`` list.

velocity / parabolic_inflow / no_slip fix all velocity components; slip fixes the normal
component on an axis-aligned boundary; do_nothing (and every unlisted boundary) is the
natural condition σ·n = 0. When no boundary is natural the pressure is pinned to 0 at
one point (the closed-cavity null space).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from ..config.fluid import BoundaryCondition
from ..config.loader import ConfigError
from ..config.mesh import box_boundary_names, former_name_message
from ..mesh.build import mesh_extent


def _ramp(t: float, ramp: float) -> float:
    return 1.0 if ramp <= 0 or t >= ramp else 0.5 * (1 - np.cos(np.pi * t / ramp))


def _allreduce(comm, arr: np.ndarray, op) -> np.ndarray:
    """Element-wise Allreduce of a float array (the pickle-based allreduce is not element-wise)."""
    out = np.empty_like(np.asarray(arr, dtype=float))
    comm.Allreduce(np.ascontiguousarray(arr, dtype=float), out, op=op)
    return out


def _facet_box(ns, facets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global bounding box of the vertices of the given (local) facets."""
    mesh = ns.mesh
    fdim = mesh.topology.dim - 1
    gdim = mesh.geometry.dim
    nodes = fem.locate_dofs_topological(ns.Q, fdim, facets)   # collective: every rank calls it
    if len(nodes):
        xs = ns.Q.tabulate_dof_coordinates()[nodes, :gdim]
        lo, hi = xs.min(axis=0), xs.max(axis=0)
    else:
        lo, hi = np.full(gdim, np.inf), np.full(gdim, -np.inf)
    return _allreduce(ns.comm, lo, MPI.MIN), _allreduce(ns.comm, hi, MPI.MAX)


def _flat_axis(ns, name: str, facets: np.ndarray) -> tuple[int, float, np.ndarray, np.ndarray]:
    """Normal axis of an axis-aligned planar boundary, the inward sign, and its bounding box."""
    lo, hi = _facet_box(ns, facets)
    ext = hi - lo
    scale = max(float(ext.max()), 1e-300)
    flat = np.flatnonzero(ext <= 1e-9 * scale)
    if len(flat) != 1:
        raise ConfigError(f"key 'fluid.boundaries': boundary {name!r} is not an axis-aligned plane "
                          f"(extent {ext.tolist()}); slip and parabolic_inflow need one")
    axis = int(flat[0])
    x = ns.mesh.geometry.x[:, axis]
    mlo = ns.comm.allreduce(x.min() if len(x) else np.inf, op=MPI.MIN)
    sign = 1.0 if abs(lo[axis] - mlo) <= 1e-9 * scale else -1.0
    return axis, sign, lo, hi


@dataclass
class BCSet:
    """The Dirichlet conditions and how to refresh their values at time t."""

    bcs: list = field(default_factory=list)
    updaters: list = field(default_factory=list)
    pinned_pressure: bool = False
    pinned_point: np.ndarray | None = None     # coordinates of the pinned pressure node
    natural_facets: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))  # owned, local

    def update(self, t: float) -> None:
        for upd in self.updaters:
            upd(t)


def velocity_bc(ns, facets: np.ndarray, fn: Callable[[np.ndarray, float], np.ndarray], bcset: BCSet,
                steady: bool = False) -> None:
    """Velocity u = fn(x, t) on the given facets (all components); ``steady``: fn does not depend
    on t, so it is interpolated once. The values are interpolated on the cells at the facets only."""
    mesh = ns.mesh
    fdim = mesh.topology.dim - 1
    gdim = mesh.geometry.dim
    mesh.topology.create_connectivity(fdim, fdim + 1)
    cells = dmesh.compute_incident_entities(mesh, facets, fdim, fdim + 1)
    g = fem.Function(ns.V)
    w_to_v = np.empty(len(ns.U.x.array), dtype=np.int32)     # W index of a velocity dof → V index
    w_to_v[ns.V_map] = np.arange(len(ns.V_map), dtype=np.int32)
    for axis in range(gdim):
        W_i = ns.velocity_subspace(axis)
        V_i, _ = W_i.collapse()
        w_dofs = fem.locate_dofs_topological((W_i, V_i), fdim, facets)[0]
        bcset.bcs.append(fem.dirichletbc(g, [w_dofs, w_to_v[w_dofs]], W_i))

    def update(t: float) -> None:
        g.interpolate(lambda x: fn(x, t), cells)
    update(ns.t)
    if not steady:
        bcset.updaters.append(update)


def _one(ns, bc: BoundaryCondition, bcset: BCSet) -> None:
    facets = ns.boundary_facets(bc.boundary)
    gdim = ns.mesh.geometry.dim
    fdim = ns.mesh.topology.dim - 1
    if bc.kind == "do_nothing":
        return
    if bc.kind == "no_slip":
        velocity_bc(ns, facets, lambda x, t: np.zeros((gdim, x.shape[1])), bcset, steady=True)
    elif bc.kind == "velocity":
        if len(bc.value) != gdim:
            raise ConfigError(f"key 'fluid.boundaries': {bc.boundary!r} value {list(bc.value)} needs {gdim} entries")
        val = np.asarray(bc.value, dtype=float)[:, None]
        velocity_bc(ns, facets, lambda x, t: np.tile(val * _ramp(t, bc.ramp_time), (1, x.shape[1])), bcset,
                    steady=bc.ramp_time <= 0)
    elif bc.kind == "parabolic_inflow":
        axis, sign, lo, hi = _flat_axis(ns, bc.boundary, facets)

        def profile(x, t):
            prof = np.full(x.shape[1], bc.max_speed * _ramp(t, bc.ramp_time))
            for j in range(gdim):
                if j != axis:
                    L = hi[j] - lo[j]
                    prof *= np.clip(4 * (x[j] - lo[j]) * (hi[j] - x[j]) / L ** 2, 0, None)
            out = np.zeros((gdim, x.shape[1]))
            out[axis] = sign * prof
            return out
        velocity_bc(ns, facets, profile, bcset, steady=bc.ramp_time <= 0)
    elif bc.kind == "slip":
        axis, _, _, _ = _flat_axis(ns, bc.boundary, facets)
        W_i = ns.velocity_subspace(axis)
        Vi, _ = W_i.collapse()
        zero = fem.Function(Vi)
        dofs = fem.locate_dofs_topological((W_i, Vi), fdim, facets)
        bcset.bcs.append(fem.dirichletbc(zero, dofs, W_i))


def _pin_pressure(ns, point, bcset: BCSet) -> None:
    """p = 0 at the pressure node nearest to ``point`` (one node globally)."""
    X = ns.Q.tabulate_dof_coordinates()
    nown = ns.Q.dofmap.index_map.size_local
    gdim = ns.mesh.geometry.dim
    pt = np.zeros(3)
    pt[:len(point)] = point
    d = np.linalg.norm(X[:nown] - pt, axis=1) if nown else np.array([np.inf])
    i = int(np.argmin(d))
    best = ns.comm.allreduce((float(d[i]), ns.comm.rank), op=MPI.MINLOC)
    target = ns.comm.bcast(X[i] if ns.comm.rank == best[1] else None, root=best[1])
    tol = 1e-12 * max(1.0, float(np.abs(target).max()))
    dofs = fem.locate_dofs_geometrical((ns.pressure_subspace, ns.Q),
                                       lambda x: np.linalg.norm(x[:gdim].T - target[:gdim], axis=1) <= tol)
    zero = fem.Function(ns.Q)
    bcset.bcs.append(fem.dirichletbc(zero, dofs, ns.pressure_subspace))
    bcset.pinned_pressure = True
    bcset.pinned_point = np.asarray(target[:gdim], dtype=float)


def unknown_boundary(ns, name: str) -> str:
    """The error for a boundary name the mesh does not have: the names it has and, on a mesh
    box, the axis name of a former name (``left`` → ``xmin``)."""
    dim = ns.mesh.geometry.dim
    why = former_name_message(name, dim) if set(box_boundary_names(dim)) <= set(ns.boundary_names) else None
    return (f"key 'fluid.boundaries': boundary {name!r} is not a mesh boundary; "
            f"known: {', '.join(sorted(ns.boundary_names)) or 'none'}" + (f" ({why})" if why else ""))


def build_bcs(ns, configs, custom: dict | None = None) -> BCSet:
    """Dirichlet conditions for every configured boundary; pin p when no boundary is natural.

    ``custom`` maps boundary names to ``fn(x, t) -> (gdim, n)`` velocity callables (e.g. an
    exact solution), used instead of a configured condition on that boundary.
    """
    bcset = BCSet()
    custom = dict(custom or {})
    configs = [bc for bc in configs if bc.boundary not in custom]
    for name, fn in custom.items():
        velocity_bc(ns, ns.boundary_facets(name), fn, bcset)
    for bc in configs:
        if bc.boundary not in ns.boundary_names:
            raise ConfigError(unknown_boundary(ns, bc.boundary))
        _one(ns, bc, bcset)
    mesh = ns.mesh
    fdim = mesh.topology.dim - 1
    mesh.topology.create_connectivity(fdim, fdim + 1)
    from dolfinx.mesh import exterior_facet_indices
    ext = exterior_facet_indices(mesh.topology)
    essential = [ns.boundary_facets(bc.boundary) for bc in configs if bc.kind != "do_nothing"]
    essential += [ns.boundary_facets(name) for name in custom]
    covered = np.unique(np.concatenate(essential)) if essential else np.array([], dtype=np.int32)
    nown = mesh.topology.index_map(fdim).size_local
    bcset.natural_facets = np.setdiff1d(ext[ext < nown], covered).astype(np.int32)
    if ns.comm.allreduce(bcset.natural_facets.size, op=MPI.SUM) == 0:
        ref = ns.config.pressure_reference
        if ref is None:
            ref = mesh_extent(mesh)[0]
        _pin_pressure(ns, ref, bcset)
    return bcset

