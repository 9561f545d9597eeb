"""The blocks' output of a coupled run, a stage of the coupled step that owns its files:

- ``bodies.csv``: every block's pose, velocity and fluid load each step;
- ``bond_breaks.csv``: the bonds that broke during each step (time, bond, its two blocks),
  the failure sequence of a structure;
- ``member_loads.csv``: each building member's largest traction / σ_c so far (1 once a bond
  point of the member reached its strength): how close each wall, column and slab came to
  failing, and when;
- ``blocks_NNNNN.vtp`` + ``blocks.pvd`` at every field output: every sphere with its radius,
  block, velocity and its block's ``damage`` (fraction of its bonds broken), opening in
  ParaView beside ``fields.xdmf``.

Rank 0 writes; every file continues from a checkpoint on restart (:meth:`BodyOutput.resume`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config.case import Case
from ..io.csv import TimeSeriesCSV

BODY_COLUMNS = (("x", "m"), ("y", "m"), ("z", "m"), ("qw", "-"), ("qx", "-"), ("qy", "-"), ("qz", "-"),
                ("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"), ("wx", "rad/s"), ("wy", "rad/s"), ("wz", "rad/s"),
                ("fx", "N"), ("fy", "N"), ("fz", "N"), ("tx", "N m"), ("ty", "N m"), ("tz", "N m"))


def member_column(member: str) -> str:
    """The ``member_loads.csv`` column of a building member: its name with ``_`` for spaces
    (``wall xmax s0`` → ``wall_xmax_s0``)."""
    return member.replace(" ", "_")


class BodyOutput:
    """The files above for the ``nb`` blocks of ``case`` under ``out_dir`` (None: none);
    ``bonds`` the DEM's cohesive bonds or None; ``rank`` this MPI rank."""

    def __init__(self, case: Case, nb: int, bonds, out_dir: Path | None, rank: int) -> None:
        self.nb, self.bonds, self.rank = nb, bonds, rank
        self.bodies_csv = self.breaks_csv = self.members_csv = None
        self.members = None
        if out_dir is not None:
            self.bodies_csv = TimeSeriesCSV(Path(out_dir) / "bodies.csv", {"t": "s", "block": "-", **dict(BODY_COLUMNS)},
                                            rank, lazy=True)
        if out_dir is not None and bonds is not None:
            self.breaks_csv = TimeSeriesCSV(Path(out_dir) / "bond_breaks.csv",
                                            {"t": "s", "bond": "-", "block_a": "-", "block_b": "-"}, rank, lazy=True)
            if case.dem.structure is not None:
                from ..dem.failure_sequence import block_members
                self.members = block_members(case)
                columns = {member_column(m): "sigma_c" for m in sorted(set(self.members))}
                self.members_csv = TimeSeriesCSV(Path(out_dir) / "member_loads.csv", {"t": "s", **columns}, rank,
                                                 lazy=True)
        self._broken_before = bonds.broken_bonds() if bonds is not None else None
        self.blocks_dir = Path(out_dir) if out_dir is not None and case.output.xdmf else None
        self.blocks_pvd: list[tuple[float, str]] = []

    def step(self, t: float, state, force: np.ndarray, torque: np.ndarray) -> None:
        """After a coupled step ending at ``t`` [s]: the blocks' rows of ``bodies.csv`` (the DEM
        ``state``, the fluid's ``force`` (nb, 3) [N] and ``torque`` [N m]), the bonds broken in
        the step, the members' peak loads."""
        self._write_bodies(t, state, force, torque)
        self._record_bond_breaks(t)
        self._record_member_loads(t)

    def _write_bodies(self, t: float, st, force: np.ndarray, torque: np.ndarray) -> None:
        if self.bodies_csv is None:
            return
        for b in range(self.nb):
            row = {"t": t, "block": b}
            for k, key in enumerate("xyz"):
                row[key] = st.pos[b, k]
                row[f"v{key}"] = st.vel[b, k]
                row[f"w{key}"] = st.omega[b, k]
                row[f"f{key}"] = force[b, k]
                row[f"t{key}"] = torque[b, k]
            for k, key in enumerate(("qw", "qx", "qy", "qz")):
                row[key] = st.quat[b, k]
            self.bodies_csv.write(**row)

    def _record_bond_breaks(self, t: float) -> None:
        if self.breaks_csv is None:
            return
        now = self.bonds.broken_bonds()
        new = np.flatnonzero(now & ~self._broken_before)
        self._broken_before = now
        for bond in new:
            p = np.flatnonzero(self.bonds.pt_bond == bond)[0]
            self.breaks_csv.write(t=t, bond=bond, block_a=self.bonds.pt_a[p], block_b=self.bonds.pt_b[p])

    def _record_member_loads(self, t: float) -> None:
        if self.members_csv is None:
            return
        from ..dem.bond_report import member_peak_tractions
        peaks = member_peak_tractions(self.bonds, self.bonds.lam_max, self.bonds.broken, self.members)
        self.members_csv.write(t=t, **{member_column(m): v for m, v in peaks.items()})

    def fields(self, t: float, state) -> None:
        """At a field output (rank 0 writes): ``blocks_NNNNN.vtp``, listed with its time in
        ``blocks.pvd``."""
        if self.blocks_dir is None or self.rank != 0:
            return
        from ..dem.output import write_vtp
        from ..io.vtp import write_pvd
        damage = self.bonds.block_damage(self.nb) if self.bonds is not None else np.zeros(self.nb)
        name = f"blocks_{len(self.blocks_pvd):05d}.vtp"
        write_vtp(self.blocks_dir / name, state, {"damage": damage[state.sph_block]})
        self.blocks_pvd.append((float(t), name))
        write_pvd(self.blocks_dir / "blocks.pvd", self.blocks_pvd)

    def resume(self, time: float) -> None:
        """Continue the files of the run a checkpoint at ``time`` [s] came from (after the DEM
        state was restored: bonds broken before it are not new)."""
        if self.blocks_dir is not None:
            from ..io.vtp import read_pvd
            self.blocks_pvd = read_pvd(self.blocks_dir / "blocks.pvd", time)
        for csv in (self.bodies_csv, self.breaks_csv, self.members_csv):
            if csv is not None:
                csv.resume(time)
        if self.bonds is not None:
            self._broken_before = self.bonds.broken_bonds()
