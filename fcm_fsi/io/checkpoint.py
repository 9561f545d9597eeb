"""HDF5 checkpoints (h5py, written by rank 0) and restart.

Each rank's local arrays (owned + ghost values of its partition) are gathered to rank 0
and stored as ``/<name>/rank_<r>``; restart scatters them back. A restart therefore
needs the same number of ranks and the same case (its fingerprint is stored); anything
else is refused with a message. The file is written to a temporary name and renamed,
so a crash while writing leaves the previous checkpoint intact.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ..config.loader import ConfigError, to_dict


def case_fingerprint(case) -> str:
    """Hash of the resolved case, ignoring what a restart may change (end time, cadence, output)."""
    data = to_dict(case)
    for key in ("t_end", "log_every", "output_every", "checkpoint_every"):
        data["run"].pop(key, None)
    data.pop("output", None)
    data.pop("description", None)
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


@dataclass
class Checkpoint:
    step: int
    time: float
    dt: float
    arrays: dict[str, np.ndarray]


def write_checkpoint(path: Path, comm: MPI.Comm, fingerprint: str, step: int, time: float, dt: float,
                     arrays: dict[str, np.ndarray]) -> None:
    """Collective: gather ``arrays`` to rank 0 and write them atomically to ``path``."""
    gathered = {name: comm.gather(np.ascontiguousarray(a), root=0) for name, a in arrays.items()}
    if comm.rank == 0:
        import h5py
        path = Path(path)
        tmp = path.with_suffix(".tmp.h5")
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"step": step, "time": time, "dt": dt, "ranks": comm.size,
                            "fingerprint": fingerprint, "format": "fcm_fsi-checkpoint-1"})
            for name, parts in gathered.items():
                g = f.create_group(name)
                for r, a in enumerate(parts):
                    g.create_dataset(f"rank_{r}", data=a)
        os.replace(tmp, path)
    comm.barrier()


def read_checkpoint(path: Path, comm: MPI.Comm, fingerprint: str) -> Checkpoint:
    """Collective: read a checkpoint written by :func:`write_checkpoint`; refuse mismatches."""
    error, meta, parts = None, None, None
    if comm.rank == 0:
        import h5py
        path = Path(path)
        try:
            with h5py.File(path, "r") as f:
                a = dict(f.attrs)
                if a.get("format") != "fcm_fsi-checkpoint-1":
                    raise ConfigError(f"{path}: not an fcm_fsi checkpoint")
                if int(a["ranks"]) != comm.size:
                    raise ConfigError(f"{path}: written by {int(a['ranks'])} rank(s), this run has {comm.size}; "
                                      f"restart with mpirun -n {int(a['ranks'])}")
                if a["fingerprint"] != fingerprint:
                    raise ConfigError(f"{path}: the case changed since this checkpoint was written "
                                      "(only run.t_end, cadences and output may change on restart)")
                meta = (int(a["step"]), float(a["time"]), float(a["dt"]))
                parts = {name: [f[name][f"rank_{r}"][...] for r in range(comm.size)] for name in f}
        except FileNotFoundError:
            error = f"{path}: checkpoint file not found"
        except OSError as err:
            error = f"{path}: cannot read checkpoint ({err})"
        except ConfigError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error:
        raise ConfigError(error)
    meta = comm.bcast(meta, root=0)
    names = comm.bcast(list(parts) if parts else [], root=0)
    arrays = {name: comm.scatter(parts[name] if comm.rank == 0 else None, root=0) for name in names}
    return Checkpoint(meta[0], meta[1], meta[2], arrays)
