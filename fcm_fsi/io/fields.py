"""XDMF field output (ParaView: open fields.xdmf, choose the Xdmf3ReaderT reader)."""
from __future__ import annotations

from pathlib import Path

from dolfinx import fem
from dolfinx.io import XDMFFile


class FieldWriter:
    """Writes the mesh once and the given P1 fields at each call.

    dolfinx rewrites the XML index after every write, so a killed run leaves a readable
    file with every completed output time. After a restart a new file
    ``fields_from_step<N>.xdmf`` is started so earlier output is never overwritten.
    """

    def __init__(self, path: Path, msh, functions: list[fem.Function]):
        self.functions = functions
        self.file = XDMFFile(msh.comm, str(path), "w")
        self.file.write_mesh(msh)

    def write(self, t: float) -> None:
        for f in self.functions:
            self.file.write_function(f, t)

    def close(self) -> None:
        self.file.close()
