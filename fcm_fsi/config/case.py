"""The whole case file: one frozen dataclass per section."""
from __future__ import annotations

import copy
import difflib
from dataclasses import dataclass
from pathlib import Path

from .coupling import CouplingConfig
from .dem import DEMConfig
from .fields import param
from .fluid import FluidConfig
from .loader import ConfigError, Variant, apply_override, build, read_yaml
from .mesh import MeshConfig, former_name_message
from .output import OutputConfig
from .pd import PDConfig
from .phase_field import PhaseFieldConfig
from .run import RunConfig


@dataclass(frozen=True, kw_only=True)
class Case:
    """A simulation case. Which physics run follows from which sections are present."""

    name: str = param(doc="case name, used in logs and output")
    description: str = param("", doc="free text")
    run: RunConfig = param(doc="time stepping and reporting")
    mesh: MeshConfig | None = param(None, doc="background mesh (required with fluid or phase_field)")
    phase_field: PhaseFieldConfig | None = param(None, doc="free surface / advected interface")
    fluid: FluidConfig | None = param(None, doc="Navier–Stokes fluid")
    dem: DEMConfig | None = param(None, doc="discrete-element blocks")
    pd: PDConfig | None = param(None, doc="peridynamic solid (alone: a pd case; docs/peridynamics.md)")
    coupling: CouplingConfig = param(default_factory=CouplingConfig,
                                     doc="fluid ⇄ DEM coupling (used when both fluid and dem are given)")
    output: OutputConfig = param(default_factory=OutputConfig, doc="output settings")

    def __post_init__(self) -> None:
        if self.phase_field is None and self.fluid is None and self.dem is None and self.pd is None:
            raise ConfigError("keys 'phase_field', 'fluid', 'dem', 'pd' are all missing: the case has no physics "
                              "(give at least one)")
        if self.pd is not None:
            self._check_pd()
        if (self.phase_field is not None or self.fluid is not None) and self.mesh is None:
            raise ConfigError("key 'mesh' is required when phase_field or fluid is given")
        if self.fluid is not None:
            self._check_boundary_names()
        pf = self.phase_field
        if pf is not None and self.fluid is None and pf.velocity is None:
            raise ConfigError("key 'phase_field.velocity' is required when there is no fluid section")
        if self.run.cfl_gas is not None and (pf is None or self.fluid is None):
            raise ConfigError("key 'run.cfl_gas' applies to two-phase flow: it needs both phase_field and fluid")
        self._check_output()
        if self.fluid is not None and self.dem is not None:
            self._check_coupled()
        elif self.mesh is not None and self.mesh.structure_band is not None:
            raise ConfigError("key 'mesh.structure_band' grades the mesh around dem blocks: it needs a coupled "
                              "case (both fluid and dem sections)")

    def _check_pd(self) -> None:
        """A peridynamic solid runs alone for now (no fluid, phase field or DEM beside it)."""
        others = [k for k in ("mesh", "phase_field", "fluid", "dem") if getattr(self, k) is not None]
        if others:
            raise ConfigError(f"key 'pd': a peridynamic solid runs alone; remove key '{others[0]}' (coupling a pd "
                              "solid to other physics is not built yet)")
        n = self.run.dt / self.pd.dt
        if abs(n - round(n)) > 1e-9 * n:
            raise ConfigError(f"key 'run.dt' = {self.run.dt:.10g} s: a pd case steps run.dt in whole steps of pd.dt = "
                              f"{self.pd.dt:.10g} s; allowed: a whole multiple of it (e.g. "
                              f"{max(round(n), 1) * self.pd.dt:.10g} s)")
        steps = self.run.t_end / self.run.dt
        if abs(steps - round(steps)) > 1e-9 * steps:
            raise ConfigError(f"key 'run.t_end' = {self.run.t_end:.10g} s: a pd case runs whole steps of run.dt = "
                              f"{self.run.dt:.10g} s; allowed: a whole multiple of it (e.g. "
                              f"{max(round(steps), 1) * self.run.dt:.10g} s)")

    def _check_output(self) -> None:
        """Probes, gauges and sensors: a mesh to sit in, points of its dimension, fields it has."""
        out = self.output
        if not (out.probes or out.gauges or out.sensors):
            return
        if self.mesh is None:
            raise ConfigError("keys 'output.probes', 'output.gauges', 'output.sensors' record fields on the mesh: "
                              "a DEM-only or pd case has none")
        dim = len(self.mesh.lower)
        for i, probe in enumerate(out.probes):
            if len(probe.point) != dim:
                raise ConfigError(f"key 'output.probes[{i}].point' = {list(probe.point)} (probe {probe.name!r}): "
                                  f"give {dim} coordinates for this {dim}D mesh")
            need = {"p": self.fluid, "u": self.fluid or (self.phase_field and self.phase_field.velocity),
                    "phi": self.phase_field}
            for field in probe.fields:
                if need[field] is None:
                    section = "phase_field" if field == "phi" else "fluid"
                    raise ConfigError(f"key 'output.probes[{i}].fields' (probe {probe.name!r}): {field!r} needs a "
                                      f"'{section}' section")
        for i, gauge in enumerate(out.gauges):
            if len(gauge.position) != dim - 1:
                raise ConfigError(f"key 'output.gauges[{i}].position' = {list(gauge.position)} (gauge "
                                  f"{gauge.name!r}): give {dim - 1} coordinate(s) (the vertical line's "
                                  f"{'x' if dim == 2 else 'x, y'}) for this {dim}D mesh")
            if self.phase_field is None:
                raise ConfigError(f"key 'output.gauges[{i}]' (gauge {gauge.name!r}): a gauge records the liquid "
                                  "height ∫φ dz and needs a 'phase_field' section")
        for i, sensor in enumerate(out.sensors):
            if self.dem is None or self.fluid is None:
                raise ConfigError(f"key 'output.sensors[{i}]' (sensor {sensor.name!r}): sensors move with blocks "
                                  "and need a coupled case (fluid and dem sections)")
            if len(sensor.point) != dim:
                raise ConfigError(f"key 'output.sensors[{i}].point' = {list(sensor.point)} (sensor "
                                  f"{sensor.name!r}): give {dim} coordinates for this {dim}D mesh")

    def _check_boundary_names(self) -> None:
        """Every mesh kind names its boundaries by axis (xmin … zmax): a former name (left …
        back) is refused with the axis name it now has."""
        for i, bc in enumerate(self.fluid.boundaries):
            why = former_name_message(bc.boundary, self.mesh.dim)
            if why is not None:
                raise ConfigError(f"key 'fluid.boundaries[{i}].boundary' = {bc.boundary!r}: {why}")

    def _check_coupled(self) -> None:
        dim = len(self.mesh.lower)
        g_fluid = tuple(self.fluid.gravity) + (0.0,) * (3 - len(self.fluid.gravity))
        if any(abs(a - b) > 1e-12 * max(1.0, abs(a)) for a, b in zip(g_fluid, self.dem.gravity)):
            raise ConfigError(f"keys 'fluid.gravity' = {list(self.fluid.gravity)} and 'dem.gravity' = "
                              f"{list(self.dem.gravity)} must be the same vector (2D fluids: dem.gravity = [gx, gy, 0])")
        if dim == 2 and self.coupling.depth is None:
            raise ConfigError("key 'coupling.depth' is required for a 2D fluid with dem blocks: the out-of-plane "
                              "extent (m) that turns the fluid's force per unit depth into a force")
        meshes = [f"dem.blocks[{i}]" for i, b in enumerate(self.dem.blocks) if b.shape == "mesh"]
        meshes += [f"dem.generators[{i}].block" for i, g in enumerate(self.dem.generators) if g.block.shape == "mesh"]
        if dim == 2 and meshes:
            raise ConfigError(f"key '{meshes[0]}.shape' = 'mesh' needs a 3D fluid: a 2D fluid sees its blocks as "
                              "prisms along z, and a surface from a CAD file is no prism (use a 3D mesh, or a box "
                              "or clump block)")

    @classmethod
    def from_yaml(cls, path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Case:
        """A case file with ``key.path=value`` overrides, as ``run CASE.yaml --set ...`` reads it
        (:func:`load_case`)."""
        return load_case(path, overrides)

    @classmethod
    def from_dict(cls, data: dict, source: str = "<dict>") -> Case:
        """A case from a mapping with the case file's layout (:func:`case_from_dict`)."""
        return case_from_dict(data, source)

    @property
    def physics(self) -> str:
        """Driver name: 'phase_field', 'fluid', 'dem', 'pd' or 'coupled'."""
        if self.pd is not None:
            return "pd"
        if self.dem is not None and self.fluid is not None:
            return "coupled"
        if self.fluid is not None:
            return "fluid"
        if self.phase_field is not None:
            return "phase_field"
        return "dem"


RESOLUTION_DOC = """\
Resolution levels: a case may list named variants under the top-level key `resolutions`
(name → a mapping with the same layout as the case, merged over it) and pick one with
`resolution: <name>` (or `--set resolution=<name>`). Example: `cases/tsunami_building.yaml`
(`coarse`, `paper`). The merge replaces scalars and lists and descends into mappings. Every
variant is validated merged over the case, the chosen one and the others alike (an error names
the variant and the key, e.g. `resolutions.paper.dem.dt`), so that a level nobody has picked yet
cannot fail only on the day it is picked."""


def load_case(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Case:
    """Load and validate a case file with its resolution level (``resolution`` /
    ``resolutions``, see :data:`RESOLUTION_DOC`) and ``key.path=value`` overrides.

    Precedence: case file < resolution level < overrides. The overrides are applied before
    the merge (so that ``resolution=paper`` or ``resolutions.coarse.…`` choose and edit the
    level) and again after it, so that an option the level also sets (e.g. ``dem.dt``) takes
    the command line's value instead of being silently replaced by the level's. Every other
    level is validated too, with the same overrides."""
    data = read_yaml(Path(path))
    for assignment in overrides:
        apply_override(data, assignment)
    later = [a for a in overrides
             if a.split("=", 1)[0].strip().split(".")[0] not in ("resolution", "resolutions")]
    return _build_levels(data, str(path), later, Path(path).parent)


def block_files_resolved(data: dict, base: Path) -> dict:
    """``data`` with the relative ``file`` of every ``dem.blocks[]`` and ``dem.generators[].block``
    made relative to ``base`` (the case file's folder), so that a case runs from any directory."""
    dem = data.get("dem")
    if not isinstance(dem, dict):
        return data
    blocks = [b for b in dem.get("blocks") or () if isinstance(b, dict)] if isinstance(dem.get("blocks"), list) else []
    if isinstance(dem.get("generators"), list):
        blocks += [g["block"] for g in dem["generators"] if isinstance(g, dict) and isinstance(g.get("block"), dict)]
    for b in blocks:
        if isinstance(b.get("file"), str) and b["file"] and not Path(b["file"]).is_absolute():
            b["file"] = str(base / b["file"])
    return data


def case_from_dict(data: dict, source: str = "<dict>") -> Case:
    """Build a case from a mapping (tests and the verification runner); every resolution level
    is validated as by :func:`load_case`."""
    return _build_levels(data, source, [])


def _build_levels(data: dict, source: str, overrides: list[str], folder: Path | None = None) -> Case:
    """The case of the chosen level; the other levels are built (validated) and dropped. Block
    files are relative to ``folder`` (the case file's folder; None: the working directory)."""
    levels, chosen = _levels(data, source)
    base = {k: v for k, v in data.items() if k not in ("resolutions", "resolution")}
    order = [chosen] + [name for name in levels if name != chosen] if levels else [None]
    cases = []
    for name in order:
        merged = copy.deepcopy(base if name is None else _merged(base, levels[name]))
        for assignment in overrides:
            apply_override(merged, assignment)
        if folder is not None:
            block_files_resolved(merged, folder)
        variant = None if name is None else Variant(name, levels[name])
        where = source if name is None else f"{source} [resolution '{name}']"
        cases.append(build(Case, merged, source=where, variant=variant))
    return cases[0]


def apply_resolution(data: dict, source: str) -> dict:
    """``data`` with the chosen ``resolutions[resolution]`` merged in and both keys removed."""
    levels, chosen = _levels(data, source)
    base = {k: v for k, v in data.items() if k not in ("resolutions", "resolution")}
    return base if levels is None else _merged(base, levels[chosen])


def _levels(data: dict, source: str) -> tuple[dict | None, str | None]:
    """(``resolutions``, ``resolution``) of a case mapping, checked; (None, None) without levels."""
    levels = data.get("resolutions")
    chosen = data.get("resolution")
    if levels is None and chosen is None:
        return None, None
    if not isinstance(levels, dict) or not levels or not all(isinstance(v, dict) for v in levels.values()):
        raise ConfigError(f"{source}: key 'resolutions' must map level names to case mappings "
                          f"(needed when 'resolution' is given)")
    bad = [k for k in levels if not isinstance(k, str)]
    if bad:
        raise ConfigError(f"{source}: key 'resolutions': level name {bad[0]!r} must be text")
    if chosen is None:
        close = difflib.get_close_matches("resolution", [k for k in data if isinstance(k, str)
                                                         and k not in ("resolution", "resolutions")], n=1, cutoff=0.8)
        if close:
            raise ConfigError(f"{source}: key '{close[0]}': is not a known key; did you mean 'resolution'?")
        raise ConfigError(f"{source}: key 'resolution' is required with 'resolutions': one of "
                          f"{', '.join(map(repr, levels))}")
    if chosen not in levels:
        raise ConfigError(f"{source}: key 'resolution' = {chosen!r}: allowed {', '.join(map(repr, levels))}")
    return levels, chosen


def _merged(base: dict, extra: dict) -> dict:
    out = dict(base)
    for key, value in extra.items():
        out[key] = _merged(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out
