"""Stage (f) of the coupled step: what series.csv records of it, and the health check that
stops a diverged run.

Columns: the fluid's own (speed, CFL, volume, kinetic energy, ...), the cut (cut cells,
smallest cut fraction), the DEM sub-steps and their stability margin, the exchange check, the
implicit coupling's passes and residual, the sealed pockets, the static load, the total fluid
force, the pose and velocity of the first :data:`SERIES_BLOCKS` blocks, the liquid in the fluid
part and inside the blocks, the water level beside block 0 (2D two-phase), the broken bonds.

Health: the fluid's checks, then an energy bound — the kinetic energy of fluid and blocks may
not exceed what they have at the start plus g × their mass × the domain's height along g
(without inflow boundaries no energy enters; damping zones only take it out), so exceeding it
means the loads and speeds have run away even while φ and the block steps stay in range.
"""
from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from .. import jit
from ..dem.state import kinetic_energy
from ..fluid.probes import liquid_height

#: blocks whose pose/velocity/load columns go into series.csv (all blocks: bodies.csv)
SERIES_BLOCKS = 4

BASE_UNITS = {"cut_cells": "-", "min_cut_fraction": "-", "dem_substeps": "-", "dem_dt_margin": "-",
              "exchange_error": "-", "coupling_iterations": "-", "coupling_residual": "-",
              "pocket_nodes": "-", "vented_nodes": "-", "drained_nodes": "-", "force_x": "N", "force_y": "N",
              "force_z": "N"}


class CoupledDiagnostics:
    """The series columns and the health check (module docstring) of a coupled run. ``case``
    the case; ``comm`` the communicator; ``fluid`` the fluid model; ``cuts`` the CutStage;
    ``exchange`` the ExchangeStage; ``dem`` the DEMSubcycler; ``implicit`` the
    ImplicitIteration; ``bonds`` the cohesive bonds or None; ``mass``, ``inertia`` the blocks'
    own (body frame); ``rho`` the fluid's density (field or constant); ``depth`` [m] the span
    of a 2D fluid; ``h_min``, ``h_max`` the smallest and largest cell diameters [m]."""

    def __init__(self, case, comm: MPI.Comm, fluid, cuts, exchange, dem, implicit, bonds, mass: np.ndarray,
                 inertia: np.ndarray, rho, depth: float, h_min: float, h_max: float) -> None:
        self.case, self.comm, self.fluid, self.cuts, self.exchange = case, comm, fluid, cuts, exchange
        self.dem, self.implicit, self.bonds = dem, implicit, bonds
        self.mass, self.inertia, self.rho, self.depth, self.h_min = mass, inertia, rho, depth, h_min
        self.gdim = cuts.gdim
        self.nb = dem.system.state.nb
        self.units = {**fluid.series_units, **BASE_UNITS}
        for b in range(min(self.nb, SERIES_BLOCKS)):
            for key, unit in (("x", "m"), ("y", "m"), ("z", "m"), ("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"),
                              ("wx", "rad/s"), ("wy", "rad/s"), ("wz", "rad/s")):
                self.units[f"b{b}_{key}"] = unit
        if cuts.hidden is not None:
            self.units.update({f"hidden_force_{c}": "N" for c in "xyz"[: self.gdim]})
            self.units.update({"hidden_length": "m"} if self.gdim == 2 else {"hidden_area": "m^2"})
        self._energy_limit = None
        self._water_forms, self._gauge_half_width = None, None
        if case.phase_field is not None:
            self._liquid_columns(h_max)
        if bonds is not None:
            self.units["broken_bonds"] = "-"
        if cuts.unresolved is not None:
            self.units["unresolved_blocks"] = "-"

    def _liquid_columns(self, h_max: float) -> None:
        """Liquid volume [m^d] in the fluid part and inside the blocks (fitted weights; the
        phase field is solved on the whole mesh, so water can diffuse into a block), and in 2D
        the water level on vertical mesh lines just outside block 0 (left, right): the local
        waterline for its draft, away from the walls' standing waves."""
        cut, pf = self.cuts.cut, self.fluid.pf
        cf = cut.fluid_fraction
        self._water_forms = (jit.form(pf.phi * cf * cut.dx_q), jit.form(pf.phi * (1 - cf) * cut.dx_q))
        self.units.update({"water_fluid_part": "m^d", "water_in_blocks": "m^d", "water_fluid_error": "-",
                           "liquid_volume_fluid": "m^d", "liquid_volume_error": "-"})
        if self.gdim == 2 and self.nb > 0:
            b0 = self.case.dem.blocks[0]
            half = 0.5 * b0.size[0] if b0.shape == "box" else b0.radius
            self._gauge_half_width = half + 1.5 * h_max
            self._pf_x = pf.V.tabulate_dof_coordinates()[:, :2]
            self._y_bottom = float(self.case.mesh.lower[1])
            self.units.update({"b0_level_left": "m", "b0_level_right": "m"})
        self.water0 = self.comm.allreduce(fem.assemble_scalar(self._water_forms[0]), op=MPI.SUM)
        self.liquid0 = pf.volume()[0]

    def values(self) -> dict[str, float]:
        """This step's row."""
        fluid, cuts, st = self.fluid, self.cuts, self.dem.system.state
        diag = fluid.diagnostics()
        umax = cuts.fluid_speed_max()
        diag["u_max"], diag["cfl"] = umax, umax * fluid.last_dt / self.h_min
        ex = self.dem.last
        diag.update({"cut_cells": float(cuts.stats.cut_cells), "min_cut_fraction": cuts.stats.min_cut_fraction,
                     "dem_substeps": float(ex.n_sub if ex else 0), "dem_dt_margin": float(ex.dt_over_dt_cr if ex else 0),
                     "exchange_error": self.exchange.error,
                     "coupling_iterations": float(self.implicit.iterations_done),
                     "coupling_residual": self.implicit.residual,
                     **(cuts.pockets.counts() if cuts.pockets else
                        {"pocket_nodes": 0.0, "vented_nodes": 0.0, "drained_nodes": 0.0})})
        if cuts.hidden is not None:
            diag.update({f"hidden_force_{c}": float(cuts.hidden.surface_force[:, k].sum())
                         for k, c in enumerate("xyz"[: self.gdim])})
            diag["hidden_length" if self.gdim == 2 else "hidden_area"] = float(cuts.hidden.hidden_measure.sum())
        total = self.exchange.force.sum(axis=0)
        diag.update({"force_x": total[0], "force_y": total[1], "force_z": total[2]})
        for b in range(min(self.nb, SERIES_BLOCKS)):
            for k, key in enumerate("xyz"):
                diag[f"b{b}_{key}"] = st.pos[b, k]
                diag[f"b{b}_v{key}"] = st.vel[b, k]
                diag[f"b{b}_w{key}"] = st.omega[b, k]
        if self._water_forms is not None:
            wf, wb = (self.comm.allreduce(fem.assemble_scalar(f), op=MPI.SUM) for f in self._water_forms)
            lv = fluid.pf.volume()[0]
            diag.update({"water_fluid_part": wf, "water_in_blocks": wb,
                         "water_fluid_error": (wf - self.water0) / self.water0,
                         "liquid_volume_fluid": lv, "liquid_volume_error": (lv - self.liquid0) / self.liquid0})
            if self._gauge_half_width is not None:
                x0 = st.pos[0, 0]
                diag["b0_level_left"] = self.water_level_at(x0 - self._gauge_half_width)
                diag["b0_level_right"] = self.water_level_at(x0 + self._gauge_half_width)
        if self.bonds is not None:
            diag["broken_bonds"] = float(np.count_nonzero(self.bonds.broken_bonds()))
        if cuts.unresolved is not None:      # blocks out of the cut, loaded as point particles
            diag["unresolved_blocks"] = float(np.count_nonzero(cuts.unresolved.unseen))
        return diag

    def water_level_at(self, x_target: float) -> float:
        """Water level [m] on the vertical line of P1 nodes nearest to ``x_target`` (2D):
        bottom + ∫φ dy along it (trapezoid over the nodes; collective)."""
        x, pf = self._pf_x, self.fluid.pf
        n = pf.V.dofmap.index_map.size_local
        d = np.abs(x[:n, 0] - x_target)
        i = int(np.argmin(d)) if n else -1
        cands = self.comm.allgather((float(d[i]), float(x[i, 0])) if n else (np.inf, np.nan))
        x_line = min(cands)[1]
        on = np.abs(x[:n, 0] - x_line) <= 1e-9 * max(1.0, abs(x_line))
        pts = np.concatenate(self.comm.allgather(np.c_[x[:n][on, 1], pf.phi.x.array[:n][on]]))
        pts = pts[np.argsort(pts[:, 0])]
        return liquid_height(pts[:, 0], pts[:, 1], self._y_bottom)

    def health(self, diag: dict[str, float]) -> str | None:
        """The fluid's checks, then the energy bound (module docstring)."""
        problem = self.fluid.health(diag)
        if problem is None and "kinetic_energy" in diag:
            if self._energy_limit is None:
                self._energy_limit = self._energy_bound(diag["kinetic_energy"])
            total = diag["kinetic_energy"] + self.block_kinetic_energy()
            if self._energy_limit is not None and total > self._energy_limit:
                unit = "J" if self.gdim == 3 else "J/m"
                problem = (f"kinetic energy of fluid and blocks {total:.4g} {unit} exceeds all the energy the system "
                           f"has, {self._energy_limit:.4g} {unit} (kinetic energy at the start + g × its mass × the "
                           "domain's height): the coupling has diverged")
        return problem

    def block_kinetic_energy(self) -> float:
        """Kinetic energy of the blocks [J; per unit depth in 2D, like the fluid's]."""
        return kinetic_energy(self.dem.system.state, self.mass, self.inertia) / self.depth

    def _energy_bound(self, fluid_kinetic: float) -> float | None:
        """What fluid and blocks have now plus g × their mass × the mesh's height along g; None
        (no check) with inflow boundaries."""
        fl = self.case.fluid
        if any(bc.kind in ("velocity", "parabolic_inflow") for bc in fl.boundaries):
            return None
        g = np.asarray(fl.gravity, float)
        gn = float(np.linalg.norm(g))
        mesh = self.cuts.cut.mesh
        x = mesh.geometry.x[:, : self.gdim]
        along = x @ (g / gn) if gn > 0 else np.zeros(len(x))
        lo = self.comm.allreduce(float(along.min(initial=np.inf)), op=MPI.MIN)
        hi = self.comm.allreduce(float(along.max(initial=-np.inf)), op=MPI.MAX)
        mass = self.comm.allreduce(fem.assemble_scalar(jit.form(self.rho * ufl.dx(domain=mesh))), op=MPI.SUM)
        moving = ~self.dem.system.state.fixed
        mass += float(self.mass[moving].sum()) / self.depth
        return fluid_kinetic + self.block_kinetic_energy() + gn * mass * (hi - lo)
