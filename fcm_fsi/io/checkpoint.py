"""HDF5 checkpoints (h5py, written by rank 0) and restart.

Mesh fields are stored partition-independently: each rank's owned nodal values and their
coordinates are gathered to rank 0 (``/fields/<name>/coords|values``); on restart every
rank reads them and picks the values at its own (owned + ghost) nodes by nearest-point
matching, which must be exact (the mesh partition may differ between runs). Replicated
arrays (counters, DEM state) are written once (``/globals/<name>``). A restart needs the
same case (its fingerprint is stored) and, by policy, the same number of ranks; anything
else is refused with a message. The file is written to a temporary name and renamed,
so a crash while writing leaves the previous checkpoint intact. The checkpoint it replaces
is kept as ``<name>.previous.h5`` (one interval earlier): a run that went wrong without
diverging — e.g. a block kicked by one bad step — can then
still be continued from before the event that the newest checkpoint already contains.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..config.loader import ConfigError, to_dict
from ..config.mesh import FORMER_BOX_NAMES, box_boundary_names

# Options added after checkpoints were already being written, with the value that does what
# the code did before the option existed. A checkpoint hashed without such an option is still
# accepted when the case leaves the option at that value (and only then). Add new options here.
# The section is a dotted path; a trailing "[]" names a list whose every entry has the option.
# Listed in the order the options were added.
#: top-level sections of the case added after checkpoints were written (``pd``): a case without
#: them keeps the fingerprint it had before they existed
ADDED_SECTIONS: tuple[str, ...] = ("pd",)

ADDED_OPTIONS: tuple[tuple[str, str, object], ...] = (
    ("coupling", "load_split", "owner"),
    ("coupling", "wall_motion", "block"),
    ("dem.blocks[]", "bonded", False),
    ("coupling", "added_mass_model", "volume"),
    ("dem.structure", "foundation", 0.0),
    ("fluid", "mass_consistent_convection", False),
    ("dem.blocks[]", "file", ""),
    ("dem.blocks[]", "scale", 1.0),
    ("dem.blocks[]", "fill", "clump"),
    ("dem.blocks[]", "sdf_spacing", None),
    ("dem.blocks[]", "sdf_margin", None),
    ("dem.blocks[]", "grid_size", None),
    ("dem.generators[].block", "file", ""),
    ("dem.generators[].block", "scale", 1.0),
    ("dem.generators[].block", "fill", "clump"),
    ("dem.generators[].block", "sdf_spacing", None),
    ("dem.generators[].block", "sdf_margin", None),
    ("dem.generators[].block", "grid_size", None),
    ("coupling", "unresolved_cells", 0.0),
    ("coupling", "unresolved_drag", 1.05),
)


def _option_holders(data: dict, section: str) -> list[dict]:
    """The mappings of the resolved case ``data`` that hold the options of ``section`` (a
    dotted path; ``name[]`` = every entry of that list); none where the section is absent."""
    holders = [data]
    for part in section.split("."):
        many = part.endswith("[]")
        nxt = [h.get(part[:-2] if many else part) for h in holders]
        holders = [e for v in nxt if v for e in (v if many else [v])]
    return holders


def _former_boundary_names(data: dict) -> None:
    """Put the former names (left … back) back into the resolved case ``data``'s
    ``fluid.boundaries``, as checkpoints written before the boundaries were named by axis have them."""
    fluid, mesh = data.get("fluid"), data.get("mesh")
    if not fluid or not mesh:
        return
    former = dict(zip(box_boundary_names(len(mesh["lower"])), FORMER_BOX_NAMES))
    for bc in fluid["boundaries"]:
        bc["boundary"] = former.get(bc["boundary"], bc["boundary"])


def case_fingerprint(case, legacy: bool = False, without: tuple[tuple[str, str], ...] = (),
                     former_names: bool = False) -> str:
    """Hash of the resolved case, ignoring what a restart may change: end time, cadence, output,
    and how the linear systems are solved (``fluid.petsc``, ``fluid.reuse_preconditioner``,
    ``fluid.preconditioner_steps``, ``fluid.preconditioner_max_iterations``, ``fluid.krylov_start``,
    ``phase_field.petsc`` — e.g. a direct solver after an iterative one broke down; they change
    the solution only at solver tolerance) and ``run.cfl_gas`` (a restart may loosen the step rule
    in the gas when spurious gas jets throttle a run; it changes the solution at the level of the
    time discretisation error, like the CFL-adapted steps themselves). ``legacy``: the hash of the oldest
    checkpoints, which still covered the solver options (such checkpoints are still accepted).
    ``without``: (section, key) options left out, as in checkpoints written before they existed.
    ``former_names``: the boundaries under their names before they were named by axis."""
    data = to_dict(case)
    for name in ADDED_SECTIONS:          # absent, a section added later leaves the hash as it was
        if data.get(name, 0) is None:
            data.pop(name)
    if former_names:
        _former_boundary_names(data)
    for key in ("t_end", "log_every", "output_every", "checkpoint_every"):
        data["run"].pop(key, None)
    if not legacy:
        for section, keys in (("fluid", ("petsc", "reuse_preconditioner")), ("phase_field", ("petsc",))):
            for key in keys:
                (data.get(section) or {}).pop(key, None)
    for key in ("preconditioner_steps", "preconditioner_max_iterations", "krylov_start"):   # solver options
        (data.get("fluid") or {}).pop(key, None)
    data["run"].pop("cfl_gas", None)   # the gas's Courant bound: a restart may loosen it
    # how the coupling's fixed point is solved: changes the solution at iteration_tol
    for key in ("iteration_method", "iteration_reuse"):
        (data.get("coupling") or {}).pop(key, None)
    for section, key in without:
        for holder in _option_holders(data, section):
            holder.pop(key, None)
    data.pop("output", None)
    data.pop("description", None)
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def accepted_fingerprints(case) -> tuple[str, ...]:
    """Fingerprints a checkpoint of this case may carry: the current one first, then those of
    older code — before the solver options were left out (``legacy``), and before the options
    :data:`ADDED_OPTIONS` [k:] existed, where this case keeps all of those at their
    old-behaviour values; each also with the boundaries' names from before they were named by
    axis (the same planes)."""
    data = to_dict(case)
    options = [(sec, key) for sec, key, _ in ADDED_OPTIONS]
    at_old = [all(h.get(key, value) == value for h in _option_holders(data, sec)) for sec, key, value in ADDED_OPTIONS]
    out = []
    for k in range(len(options), -1, -1):           # k = len: nothing left out (current code)
        if not all(at_old[k:]):
            continue
        for former_names, legacy in itertools.product((False, True), repeat=2):
            fp = case_fingerprint(case, legacy, tuple(options[k:]), former_names)
            if fp not in out:
                out.append(fp)
    return tuple(out)


@dataclass
class Checkpoint:
    step: int
    time: float
    dt: float
    fields: dict[str, tuple[np.ndarray, np.ndarray]]   # name → (coords, values), all nodes
    globals: dict[str, np.ndarray]


def nodal_values_at(coords: np.ndarray, stored: tuple[np.ndarray, np.ndarray], name: str) -> np.ndarray:
    """Values of a stored nodal field at ``coords`` (exact node matching)."""
    from scipy.spatial import cKDTree
    ck_coords, ck_values = stored
    dist, idx = cKDTree(ck_coords).query(coords)
    scale = max(float(np.ptp(ck_coords, axis=0).max()), 1.0)
    if dist.size and dist.max() > 1e-9 * scale:
        raise ConfigError(f"checkpoint field '{name}' was written on a different mesh "
                          f"(node mismatch {dist.max():.3g} m)")
    return ck_values[idx]


def previous_checkpoint(path: Path) -> Path:
    """Where :func:`write_checkpoint` keeps the checkpoint that ``path`` replaced."""
    path = Path(path)
    return path.with_name(path.stem + ".previous.h5")


def write_checkpoint(path: Path, comm: MPI.Comm, fingerprint: str, step: int, time: float, dt: float,
                     fields: dict[str, tuple[np.ndarray, np.ndarray]], globals_: dict[str, np.ndarray]) -> None:
    """Collective: gather owned nodal ``fields`` (coords, values) to rank 0 and write atomically;
    the file it replaces becomes :func:`previous_checkpoint`."""
    gathered = {name: (comm.gather(np.ascontiguousarray(c), root=0), comm.gather(np.ascontiguousarray(v), root=0))
                for name, (c, v) in fields.items()}
    if comm.rank == 0:
        import h5py
        path = Path(path)
        tmp = path.with_suffix(".tmp.h5")
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"step": step, "time": time, "dt": dt, "ranks": comm.size,
                            "fingerprint": fingerprint, "format": "fcm_fsi-checkpoint-2"})
            for name, (cs, vs) in gathered.items():
                g = f.create_group(f"fields/{name}")
                g.create_dataset("coords", data=np.concatenate(cs))
                g.create_dataset("values", data=np.concatenate(vs))
            for name, a in globals_.items():
                f.create_dataset(f"globals/{name}", data=a)
        if path.exists():
            os.replace(path, previous_checkpoint(path))
        os.replace(tmp, path)
    comm.barrier()


def checkpoint_attributes(path: Path, comm: MPI.Comm) -> dict:
    """The attributes of a checkpoint (step, time, dt, ranks, fingerprint, format) without its
    fields, on any rank count. Collective; {} when the file cannot be read."""
    attrs = {}
    if comm.rank == 0:
        import h5py
        try:
            with h5py.File(Path(path), "r") as f:
                attrs = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
        except OSError:
            pass
    return comm.bcast(attrs, root=0)


def read_checkpoint(path: Path, comm: MPI.Comm, fingerprint: str | tuple[str, ...]) -> Checkpoint:
    """Collective: read a checkpoint written by :func:`write_checkpoint`; refuse mismatches
    (``fingerprint``: the case's, or several accepted ones)."""
    accepted = (fingerprint,) if isinstance(fingerprint, str) else tuple(fingerprint)
    error, payload = None, None
    if comm.rank == 0:
        import h5py
        path = Path(path)
        try:
            with h5py.File(path, "r") as f:
                a = dict(f.attrs)
                if a.get("format") != "fcm_fsi-checkpoint-2":
                    raise ConfigError(f"{path}: not an fcm_fsi checkpoint")
                if int(a["ranks"]) != comm.size:
                    raise ConfigError(f"{path}: written by {int(a['ranks'])} rank(s), this run has {comm.size}; "
                                      f"restart with mpirun -n {int(a['ranks'])}")
                if a["fingerprint"] not in accepted:
                    raise ConfigError(f"{path}: the case changed since this checkpoint was written "
                                      "(only run.t_end, cadences, output and solver options may change on restart)")
                fields = {n: (g["coords"][...], g["values"][...]) for n, g in f.get("fields", {}).items()}
                globals_ = {n: d[...] for n, d in f.get("globals", {}).items()}
                payload = (int(a["step"]), float(a["time"]), float(a["dt"]), fields, globals_)
        except FileNotFoundError:
            error = f"{path}: checkpoint file not found"
        except OSError as err:
            error = f"{path}: cannot read checkpoint ({err})"
        except ConfigError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error:
        raise ConfigError(error)
    step, time, dt, fields, globals_ = comm.bcast(payload, root=0)
    return Checkpoint(step, time, dt, fields, globals_)
