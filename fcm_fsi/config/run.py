"""Time stepping, logging, output and checkpoint cadence (section ``run``)."""
from __future__ import annotations

from dataclasses import dataclass

from .fields import param
from .loader import ConfigError


@dataclass(frozen=True, kw_only=True)
class RunConfig:
    """How long and how finely to march in time, and how often to report."""

    t_end: float = param(unit="s", doc="simulated end time", gt=0)
    dt: float = param(unit="s", doc="(initial) time step of the outer (fluid or phase-field) loop", gt=0)
    cfl: float | None = param(None, doc="if set, adapt dt each step so that max|u|·dt/h stays at this Courant number",
                              gt=0, le=10)
    cfl_gas: float | None = param(None, doc="with cfl and a phase field: the Courant number allowed at the gas nodes "
                                  "(φ < 0.05); the liquid and the interface keep run.cfl (default: run.cfl everywhere). "
                                  "With coupling.added_mass_model: volume not for blocks that land in contact: the larger "
                                  "steps let the explicit coupling's force oscillation grow and kick the block "
                                  "(docs/two-phase.md)",
                                  gt=0, le=10)
    dt_max: float | None = param(None, unit="s", doc="upper bound on the adapted dt (defaults to dt)", gt=0)
    dt_growth: float | None = param(None, doc="with cfl: the adapted dt grows by at most this factor per step "
                                    "(from run.dt at the start), so a flow starting from rest is resolved while it "
                                    "accelerates (unset: no limit)", gt=1, le=10)
    log_every: int = param(10, unit="steps", doc="progress line every this many steps", ge=1)
    output_every: int = param(10, unit="steps", doc="XDMF field output every this many steps (0 = only first and last)", ge=0)
    checkpoint_every: int = param(100, unit="steps", doc="HDF5 checkpoint every this many steps (and always at the end)", ge=1)

    def __post_init__(self) -> None:
        if self.dt > self.t_end:
            raise ConfigError(f"key 'run.dt' = {self.dt} must not exceed run.t_end = {self.t_end}")
        if self.cfl_gas is not None and self.cfl is None:
            raise ConfigError("key 'run.cfl_gas' needs run.cfl (the Courant number of the liquid) to be set")
        if self.cfl_gas is not None and self.cfl_gas < self.cfl:
            raise ConfigError(f"key 'run.cfl_gas' = {self.cfl_gas} must be at least run.cfl = {self.cfl} "
                              "(it loosens the step rule in the gas, never tightens it)")
