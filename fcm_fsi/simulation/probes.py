"""``output.probes``, ``output.gauges`` and ``output.sensors``: what the time loop records at
points every step, rank 0 writing.

- ``probes.csv``: per probe the fields it asks for (NAME_p [Pa], NAME_ux, NAME_uy(, NAME_uz)
  [m/s], NAME_phi [-]) at its fixed point; per sensor NAME_p [Pa] at its point moving rigidly
  with its block;
- ``gauges.csv``: per gauge the liquid surface elevation NAME [m], the bottom of the mesh plus
  ∫φ dz along its vertical line (fluid/probes.py).

Checked when the run starts, each a ConfigError naming the probe: a point outside the mesh, a
probe point inside a block (coupled cases), a sensor on a block that does not exist.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..config.loader import ConfigError
from ..fluid.probes import PointValues, liquid_height, vertical_line
from ..geometry import quat_to_matrix_np
from ..io.csv import TimeSeriesCSV
from ..mesh.build import mesh_extent

UNITS = {"p": "Pa", "u": "m/s", "phi": "-"}


class ProbeRecorder:
    """The probes, gauges and sensors of ``case`` on ``model`` (which gives ``probe_fields()``
    and, for sensors and the inside-a-block check, ``block_poses()`` and ``solid_at(points)``);
    files in ``out``; ``resume_at`` [s] continues the files of a restarted run."""

    def __init__(self, case, model, out: Path, rank: int, resume_at: float | None = None) -> None:
        out_cfg = case.output
        self.model, self.mesh = model, model.mesh
        self.gdim = self.mesh.geometry.dim
        self.fields = model.probe_fields()
        self.probes, self.sensors, self.gauges = out_cfg.probes, out_cfg.sensors, out_cfg.gauges
        resume = dict(append=True, resume_at=resume_at) if resume_at is not None else {}
        self.probe_csv = self.gauge_csv = None
        if self.probes or self.sensors:
            self._points = np.array([p.point for p in self.probes], float).reshape(len(self.probes), -1)
            self._fields_read = sorted({f for p in self.probes for f in p.fields})
            self._fixed = PointValues(self.mesh, len(self.probes))
            self._check_probes()
            self._moving = PointValues(self.mesh, len(self.sensors))
            self._body_points = self._sensor_body_points()
            self.probe_csv = TimeSeriesCSV(out / "probes.csv", {"t": "s", **self._probe_columns()}, rank, **resume)
        if self.gauges:
            lo, hi = mesh_extent(self.mesh)
            spacing = 0.5 * model.h_min
            self._bottom = float(lo[-1])
            self._lines = [vertical_line(g.position, lo[-1], hi[-1], spacing, self.gdim) for g in self.gauges]
            self._gauge_values = PointValues(self.mesh, sum(len(line) for line in self._lines))
            self.gauge_csv = TimeSeriesCSV(out / "gauges.csv", {"t": "s", **{g.name: "m" for g in self.gauges}},
                                           rank, **resume)

    def _probe_columns(self) -> dict[str, str]:
        cols = {}
        for probe in self.probes:
            for field in probe.fields:
                if field == "u":
                    cols.update({f"{probe.name}_u{c}": "m/s" for c in "xyz"[: self.gdim]})
                else:
                    cols[f"{probe.name}_{field}"] = UNITS[field]
        cols.update({f"{s.name}_p": "Pa" for s in self.sensors})
        return cols

    def _check_probes(self) -> None:
        if not self.probes:
            return
        points = self._points
        _, _, found = self._fixed.cells(points)
        solid = self.model.solid_at(points) if hasattr(self.model, "solid_at") else np.zeros(len(points), bool)
        for i, probe in enumerate(self.probes):
            if not found[i]:
                raise ConfigError(f"key 'output.probes[{i}].point' = {list(probe.point)} (probe {probe.name!r}): "
                                  "outside the mesh")
            if solid[i]:
                raise ConfigError(f"key 'output.probes[{i}].point' = {list(probe.point)} (probe {probe.name!r}): "
                                  "inside a block at t = 0; place it in the fluid (a sensor moves with a block)")

    def _sensor_body_points(self) -> np.ndarray:
        """Each sensor's point in its block's body frame (from the poses at the start)."""
        if not self.sensors:
            return np.zeros((0, 3))
        pos, quat = self.model.block_poses()
        out = np.zeros((len(self.sensors), 3))
        for i, s in enumerate(self.sensors):
            if s.block >= len(pos):
                raise ConfigError(f"key 'output.sensors[{i}].block' = {s.block} (sensor {s.name!r}): the case has "
                                  f"{len(pos)} blocks (0 … {len(pos) - 1})")
            x = np.zeros(3)
            x[: self.gdim] = s.point
            out[i] = quat_to_matrix_np(quat[s.block]).T @ (x - pos[s.block])
        return out

    def sensor_points(self) -> np.ndarray:
        """Where the sensors are now (n, gdim) [m]."""
        pos, quat = self.model.block_poses()
        blocks = np.array([s.block for s in self.sensors], int)
        world = np.array([pos[b] + quat_to_matrix_np(quat[b]) @ x for b, x in zip(blocks, self._body_points)])
        return world.reshape(-1, 3)[:, : self.gdim]

    def record(self, t: float) -> None:
        """One row of each file at time ``t`` [s] (collective)."""
        if self.probe_csv is not None:
            row = {}
            if self.probes:
                values, _ = self._fixed.values([self.fields[f] for f in self._fields_read], self._points)
                by_field = dict(zip(self._fields_read, values))
                for i, probe in enumerate(self.probes):
                    for field in probe.fields:
                        v = by_field[field][i]
                        if field == "u":
                            row.update({f"{probe.name}_u{c}": v[k] for k, c in enumerate("xyz"[: self.gdim])})
                        else:
                            row[f"{probe.name}_{field}"] = v[0]
            if self.sensors:
                (p,), _ = self._moving.values([self.fields["p"]], self.sensor_points())
                row.update({f"{s.name}_p": p[i, 0] for i, s in enumerate(self.sensors)})
            self.probe_csv.write(t=t, **row)
        if self.gauge_csv is not None:
            (phi,), _ = self._gauge_values.values([self.fields["phi"]], np.concatenate(self._lines))
            heights, start = {}, 0
            for g, line in zip(self.gauges, self._lines):
                seg = phi[start: start + len(line), 0]
                ok = np.isfinite(seg)
                heights[g.name] = liquid_height(line[ok, -1], np.clip(seg[ok], 0.0, 1.0), self._bottom)
                start += len(line)
            self.gauge_csv.write(t=t, **heights)

    def close(self) -> None:
        for csv in (self.probe_csv, self.gauge_csv):
            if csv is not None:
                csv.close()
