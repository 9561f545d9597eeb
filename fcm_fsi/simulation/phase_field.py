"""Phase field advected by a prescribed velocity (rotating cylinder, Zalesak disk)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..config.case import Case
from ..fluid.phase_field import PhaseField
from ..fluid.prescribed import prescribed_velocity
from ..io.timing import StageTimer
from ..mesh.build import build_mesh, min_cell_size
from .loop import finite_or_message

PHI_BOUNDS = (-0.5, 1.5)  # beyond these the field has blown up: stop the run


def phase_field_health(diag: dict[str, float]) -> str | None:
    """Why a step with these diagnostics must stop (non-finite, φ out of bounds), or None."""
    problem = finite_or_message(diag)
    if problem is None and not PHI_BOUNDS[0] <= diag["phi_min"] <= diag["phi_max"] <= PHI_BOUNDS[1]:
        problem = f"φ left [{PHI_BOUNDS[0]}, {PHI_BOUNDS[1]}]: min {diag['phi_min']:.3g}, max {diag['phi_max']:.3g}"
    return problem


class PhaseFieldModel:
    """Mesh + prescribed velocity + φ; diagnostics are the case-health numbers."""

    series_units = {"mass": "m^d", "mass_drift": "-", "mass_balance_error": "-", "volume": "m^d", "volume_error": "-",
                    "interface_measure": "m^(d-1)", "phi_min": "-", "phi_max": "-", "newton_iterations": "-"}

    def __init__(self, case: Case, comm: MPI.Comm, case_dir: Path | None = None):
        cfg = case.phase_field
        self.mesh = build_mesh(case.mesh, comm, case_dir)
        self.h_min = min_cell_size(self.mesh)
        self.velocity, self.u_max = prescribed_velocity(self.mesh, cfg.velocity)
        self.pf = PhaseField(self.mesh, cfg, self.h_min, self.velocity, self.u_max, case.run.dt)
        self.pf.set_initial(cfg.initial)
        self.output_functions = [self.pf.phi, self.velocity]
        self.iterations = 0

    def advance(self, t: float, dt: float, timer: StageTimer) -> None:
        with timer("phase field"):
            self.iterations = self.pf.advance(dt)

    def stable_dt(self, cfl: float) -> float:
        return cfl * self.h_min / max(self.u_max, 1e-300)

    def diagnostics(self) -> dict[str, float]:
        mass = self.pf.mass()
        volume, area = self.pf.volume()
        phi = self.pf.phi.x.array
        comm = self.mesh.comm
        return {"mass": mass, "mass_drift": (mass - self.pf.mass0) / self.pf.mass0,
                "mass_balance_error": (mass - self.pf.mass0 + self.pf.outflow_total) / self.pf.mass0,
                "volume": volume, "volume_error": (volume - self.pf.volume0) / self.pf.volume0,
                "interface_measure": area,
                "phi_min": comm.allreduce(float(phi.min(initial=np.inf)), op=MPI.MIN),
                "phi_max": comm.allreduce(float(phi.max(initial=-np.inf)), op=MPI.MAX),
                "newton_iterations": float(self.iterations)}

    def health(self, diag: dict[str, float]) -> str | None:
        return phase_field_health(diag)

    def probe_fields(self) -> dict:
        """The fields probes record (simulation/probes.py): φ and the prescribed velocity."""
        return {"phi": self.pf.phi, "u": self.velocity}

    def state(self):
        return self.pf.state()

    def load_state(self, checkpoint) -> None:
        self.pf.load_state(checkpoint)
