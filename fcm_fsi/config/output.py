"""What is written where (section ``output``)."""
from __future__ import annotations

from dataclasses import dataclass

from .fields import param


@dataclass(frozen=True, kw_only=True)
class OutputConfig:
    """Field output (XDMF), scalar time series (CSV) and checkpoints (HDF5)."""

    directory: str = param("output", doc="output folder (relative to the working directory); --output overrides it")
    xdmf: bool = param(True, doc="write fields as an XDMF time series (fields.xdmf + .h5) for ParaView")
    checkpoint: bool = param(True, doc="write HDF5 checkpoints (checkpoint.h5) for --restart")
