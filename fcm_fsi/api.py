"""The Python API: cases built and run from a script, the command line on top of it.

    from fcm_fsi import Case, run

    case = Case.from_yaml("cases/block_overturn.yaml", ["dem.materials[0].friction_angle=20"])
    series = run(case, output="out/friction20")           # every rank gets the arrays
    print(series["t"][-1], series["b0_wz"].max())

``run`` runs any kind of case (phase field, fluid, two-phase, coupled, DEM only) on the shared
time loop, writes the usual output folder, and returns the series (``series.csv``'s columns
without units: ``step``, ``t``, ``dt``, ``retried_steps`` and the model's) as numpy arrays. Under
``mpirun`` every rank calls it with the same case and gets the same arrays. ``on_step(step, t,
row)`` is called on every rank after each step (and at the start) with that step's row.
Errors are raised as in the CLI: ``ConfigError`` (bad input, before or while setting up) and
``SimulationDiverged`` (the run stopped; the last good checkpoint stays).
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from .config.case import Case

__all__ = ["Case", "run"]


def write_resolved_case(case: Case, out: Path, rank: int) -> None:
    """The case as understood (defaults filled in), ``out/case.resolved.yaml``, by rank 0."""
    if rank == 0:
        import yaml

        from .config import to_dict
        out.mkdir(parents=True, exist_ok=True)
        (out / "case.resolved.yaml").write_text(yaml.safe_dump(to_dict(case), sort_keys=False))


def build_model(case: Case, comm, out: Path, restart: str | None, case_dir: Path | None):
    """The model of the physics present in ``case`` (the time loop's protocol)."""
    physics = case.physics
    if physics == "phase_field":
        from .simulation.phase_field import PhaseFieldModel
        return PhaseFieldModel(case, comm, case_dir)
    if physics == "fluid" and case.phase_field is not None:
        from .simulation.two_phase import TwoPhaseModel
        return TwoPhaseModel(case, comm, case_dir)
    if physics == "fluid":
        from .simulation.fluid import FluidModel
        return FluidModel(case, comm, case_dir)
    if physics == "coupled":
        from .simulation.coupled import CoupledModel
        return CoupledModel(case, comm, case_dir, out_dir=out)
    if physics == "pd":
        from .simulation.pd_model import PDModel
        return PDModel(case, comm, out, case_dir)
    from .simulation.dem_model import DEMModel
    return DEMModel(case, comm, out, restart=restart is not None)


def run(case: Case, output: str | Path | None = None, *, on_step: Callable[[int, float, dict], None] | None = None,
        restart: str | Path | None = None, comm=None, case_dir: str | Path | None = None) -> dict[str, np.ndarray]:
    """Run ``case`` into ``output`` (default: its ``output.directory``), from ``restart`` (a
    checkpoint.h5) if given, on ``comm`` (default MPI.COMM_WORLD); ``case_dir`` resolves the
    case's relative file paths (mesh files). Returns the series of this run as arrays."""
    from mpi4py import MPI

    from .simulation.loop import TimeLoop
    comm = MPI.COMM_WORLD if comm is None else comm
    out = Path(output if output is not None else case.output.directory)
    write_resolved_case(case, out, comm.rank)
    comm.barrier()
    restart = None if restart is None else str(restart)
    model = build_model(case, comm, out, restart, None if case_dir is None else Path(case_dir))
    loop = TimeLoop(case, model, out, comm, restart, on_step=on_step)
    loop.run()
    names = list(loop.rows[0]) if loop.rows else []
    return {name: np.array([row.get(name, np.nan) for row in loop.rows], float) for name in names}
