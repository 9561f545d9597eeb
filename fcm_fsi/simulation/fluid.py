"""Single-phase Navier–Stokes run by the CLI (e.g. cases/cavity_re100.yaml), and the
Navier–Stokes checkpoint helpers shared with the two-phase model."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from ..config.case import Case
from ..fluid.navier_stokes import NavierStokes, NonlinearSolveError
from ..io.timing import StageTimer
from ..mesh.build import build_mesh, min_cell_size
from ..mesh.channel import tag_box_boundaries
from .loop import SimulationDiverged, finite_or_message


def ns_state(ns: NavierStokes, gdim: int) -> tuple[dict, dict]:
    """Owned nodal (coords, values) of U, Uⁿ (velocity and pressure), uⁿ⁻¹ and the last updates
    of the linearised step (the start of its Krylov solve), and the updates' steps and Δt."""
    nv, nq = ns.V.dofmap.index_map.size_local, ns.Q.dofmap.index_map.size_local
    xv, xq = ns.V.tabulate_dof_coordinates()[:nv], ns.Q.tabulate_dof_coordinates()[:nq]
    fields = {}
    arrays = [("U", ns.U.x.array), ("U_n", ns.U_n.x.array)]
    increments = [] if ns.increments is None else [("dU_last", ns.increments.last), ("dU_before", ns.increments.before)]
    arrays += [(name, inc.values) for name, inc in increments if inc is not None]
    for name, arr in arrays:
        fields[f"{name}_u"] = (xv, arr[ns.V_map].reshape(-1, gdim)[:nv].copy())
        fields[f"{name}_p"] = (xq, arr[ns.Q_map][:nq].copy())
    fields["u_nm1"] = (xv, ns.u_nm1.x.array.reshape(-1, gdim)[:nv].copy())
    steps = [(inc.step, inc.dt) if inc is not None else (np.nan, np.nan) for _, inc in increments]
    return fields, {"ns_increments": np.array(steps, dtype=float).reshape(-1, 2)}


def ns_load_state(ns: NavierStokes, checkpoint) -> None:
    """Inverse of :func:`ns_state` (nodes matched by coordinates)."""
    from ..io.checkpoint import nodal_values_at
    xv, xq = ns.V.tabulate_dof_coordinates(), ns.Q.tabulate_dof_coordinates()

    def array(name: str) -> np.ndarray:
        out = np.zeros_like(ns.U.x.array)
        out[ns.V_map] = nodal_values_at(xv, checkpoint.fields[f"{name}_u"], f"{name}_u").ravel()
        out[ns.Q_map] = nodal_values_at(xq, checkpoint.fields[f"{name}_p"], f"{name}_p")
        return out
    ns.U.x.array[:], ns.U_n.x.array[:] = array("U"), array("U_n")
    ns.u_nm1.x.array[:] = nodal_values_at(xv, checkpoint.fields["u_nm1"], "u_nm1").ravel()
    if ns.increments is not None:
        ns.increments.clear()
        steps = checkpoint.globals.get("ns_increments", np.zeros((0, 2)))
        for name, (step, dt) in reversed(list(zip(("dU_last", "dU_before"), steps))):
            if np.isfinite(step) and f"{name}_u" in checkpoint.fields:
                ns.increments.record(int(step), float(dt), array(name))


def ns_snapshot(ns: NavierStokes) -> tuple:
    """Local copies (ghosts included) of what a step changes in ``ns``: U, Uⁿ, uⁿ⁻¹, t, the step
    count and the length of the solve history (:func:`ns_restore`)."""
    return (ns.U.x.array.copy(), ns.U_n.x.array.copy(), ns.u_nm1.x.array.copy(), ns.t, ns.step_count,
            len(ns.history))


def ns_restore(ns: NavierStokes, snap: tuple) -> None:
    """Inverse of :func:`ns_snapshot`."""
    U, U_n, u_nm1, ns.t, ns.step_count, nhist = snap
    ns.U.x.array[:], ns.U_n.x.array[:], ns.u_nm1.x.array[:] = U, U_n, u_nm1
    del ns.history[nhist:]


def max_speed(ns: NavierStokes, gdim: int, comm: MPI.Comm) -> float:
    """max |u| over the mesh [m/s] (collective)."""
    u = ns.U.x.array[ns.V_map].reshape(-1, gdim)
    return comm.allreduce(float(np.sqrt((u ** 2).sum(axis=1)).max(initial=0.0)), op=MPI.MAX)


class FluidModel:
    """Incompressible single-phase flow on a rectangle/box whose sides are named by axis,
    xmin/xmax/ymin/ymax(/zmin/zmax), in ``fluid.boundaries``."""

    series_units = {"u_max": "m/s", "cfl": "-", "divergence_l2": "1/s", "ns_iterations": "-"}

    def __init__(self, case: Case, comm: MPI.Comm, case_dir: Path | None = None, *, mesh=None,
                 ns_options: dict | None = None):
        self.mesh = mesh if mesh is not None else build_mesh(case.mesh, comm, case_dir)
        self.gdim = self.mesh.geometry.dim
        self.h_min = min_cell_size(self.mesh)
        tagged = tag_box_boundaries(self.mesh, case.mesh.lower, case.mesh.upper)
        self.ns = NavierStokes(self.mesh, case.fluid, case.run.dt, facet_tags=tagged.facet_tags,
                               boundary_names=tagged.names, **(ns_options or {}))
        self.u_out = fem.Function(self.ns.V)
        self.u_out.name = "u"
        self.p_out = fem.Function(self.ns.Q)
        self.p_out.name = "p"
        self.output_functions = [self.u_out, self.p_out]
        self.last_dt = case.run.dt
        self.iterations = 0

    def advance(self, t: float, dt: float, timer: StageTimer, retake: bool = False) -> None:
        """One step of the flow. ``retake``: the step is taken again from the same start on the
        same cut (an implicit coupling's later pass, whose wall velocity alone differs): the
        flow's matrix is kept (``NavierStokes.step``)."""
        with timer("navier-stokes"):
            self.ns.dt.value = dt
            try:
                self.iterations = self.ns.step(same_operator=retake).iterations
            except NonlinearSolveError as err:
                raise SimulationDiverged(str(err)) from err
        self.u_out.x.array[:] = self.ns.U.x.array[self.ns.V_map]
        self.p_out.x.array[:] = self.ns.U.x.array[self.ns.Q_map]
        self.last_dt = dt

    def stable_dt(self, cfl: float) -> float:
        umax = max_speed(self.ns, self.gdim, self.mesh.comm)
        return cfl * self.h_min / umax if umax > 0 else np.inf

    def diagnostics(self) -> dict[str, float]:
        umax = max_speed(self.ns, self.gdim, self.mesh.comm)
        return {"u_max": umax, "cfl": umax * self.last_dt / self.h_min,
                "divergence_l2": self.ns.divergence_l2(), "ns_iterations": float(self.iterations)}

    def health(self, diag: dict[str, float]) -> str | None:
        return finite_or_message(diag)

    def halves(self, dt: float) -> bool:
        """Any step may be retaken as two half steps (the loop's retaken steps)."""
        return True

    def probe_fields(self) -> dict:
        """The fields probes record (simulation/probes.py)."""
        return {"p": self.p_out, "u": self.u_out}

    def snapshot(self) -> tuple:
        """What a step changes, to take it again (:meth:`restore`)."""
        return ns_snapshot(self.ns), self.last_dt

    def restore(self, snap: tuple) -> None:
        ns, self.last_dt = snap
        ns_restore(self.ns, ns)

    def state(self):
        fields, globals_ = ns_state(self.ns, self.gdim)
        globals_["fluid_scalars"] = np.array([self.ns.t, float(self.ns.step_count)])
        return fields, globals_

    def load_state(self, checkpoint) -> None:
        ns_load_state(self.ns, checkpoint)
        t, steps = checkpoint.globals["fluid_scalars"]
        self.ns.t, self.ns.step_count = float(t), int(steps)
        self.u_out.x.array[:] = self.ns.U.x.array[self.ns.V_map]
        self.p_out.x.array[:] = self.ns.U.x.array[self.ns.Q_map]
