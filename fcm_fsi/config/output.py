"""What is written where (section ``output``)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .fields import param
from .loader import ConfigError

#: the fields a probe can record and the columns each gives (u: one per velocity component)
PROBE_FIELDS = ("p", "u", "phi")


@dataclass(frozen=True, kw_only=True)
class Probe:
    """A fixed point where fields are recorded every step (``probes.csv``): the value of the
    field's finite-element interpolant in the cell that holds the point."""

    name: str = param(doc="the probe's name: its columns in probes.csv are NAME_p, NAME_ux, ... NAME_phi")
    point: tuple[float, ...] = param(unit="m", doc="(x, y) in 2D, (x, y, z) in 3D; inside the mesh, in the fluid")
    fields: tuple[Literal["p", "u", "phi"], ...] = param(
        ("p",), doc="what to record: p (total pressure, Pa), u (velocity, m/s), phi (phase field, two-phase only)")

    def __post_init__(self) -> None:
        if not self.fields:
            raise ConfigError(f"probe {self.name!r}: key 'fields' is empty; allowed: any of {', '.join(PROBE_FIELDS)}")
        if len(set(self.fields)) != len(self.fields):
            raise ConfigError(f"probe {self.name!r}: key 'fields' = {list(self.fields)} names a field twice")


@dataclass(frozen=True, kw_only=True)
class Gauge:
    """A vertical line (along the last axis, against gravity) on which the liquid height
    ∫φ dz is recorded every step (``gauges.csv``): the free-surface elevation of a wave gauge."""

    name: str = param(doc="the gauge's name: its column in gauges.csv")
    position: tuple[float, ...] = param(unit="m", doc="(x) in 2D, (x, y) in 3D: where the vertical line stands")


@dataclass(frozen=True, kw_only=True)
class Sensor:
    """A pressure sensor on a block: a point given at t = 0 that moves with the block (rigidly),
    recording the fluid's total pressure there every step (``probes.csv``, column NAME_p). Place
    it on the wetted face, or just off it in the fluid."""

    name: str = param(doc="the sensor's name: its column in probes.csv is NAME_p")
    block: int = param(doc="index of the block it is fixed to (order of dem.blocks, counts expanded)", ge=0)
    point: tuple[float, ...] = param(unit="m", doc="(x, y) in 2D, (x, y, z) in 3D at t = 0")


@dataclass(frozen=True, kw_only=True)
class OutputConfig:
    """Field output (XDMF), scalar time series (CSV), checkpoints (HDF5), probes and gauges."""

    directory: str = param("output", doc="output folder (relative to the working directory); --output overrides it")
    xdmf: bool = param(True, doc="write fields as an XDMF time series (fields.xdmf + .h5) for ParaView")
    checkpoint: bool = param(True, doc="write HDF5 checkpoints (checkpoint.h5) for --restart")
    probes: tuple[Probe, ...] = param(default_factory=tuple, doc="points recording p, u, φ every step (probes.csv)")
    gauges: tuple[Gauge, ...] = param(default_factory=tuple,
                                      doc="vertical lines recording the liquid height every step (gauges.csv)")
    sensors: tuple[Sensor, ...] = param(default_factory=tuple,
                                        doc="pressure sensors moving with blocks, coupled cases (probes.csv)")

    def __post_init__(self) -> None:
        names = [p.name for p in self.probes] + [s.name for s in self.sensors]
        for group, key in ((names, "probes/sensors"), ([g.name for g in self.gauges], "gauges")):
            twice = sorted({n for n in group if group.count(n) > 1})
            if twice:
                raise ConfigError(f"key 'output.{key}': the name {twice[0]!r} is used twice (names become columns)")
