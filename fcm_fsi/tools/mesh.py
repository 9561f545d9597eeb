"""Generate a case's gmsh mesh without running it: ``python -m fcm_fsi mesh CASE [--set K=V]
[--write FILE.msh]``. Prints the cell and vertex counts, the cell sizes and what the
generation cost (time, peak memory of this process), so that a mesh too large for the
machine is found before a run, and a cluster run can be meshed once on a large node
(``--write``, then ``mesh.kind: gmsh_file``). One process, no MPI."""
from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

from ..config.case import load_case
from ..config.loader import ConfigError

EXIT_BAD_INPUT = 2


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("case", type=Path, help="case file (YAML)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE", help="override a case value (repeatable)")
    ap.add_argument("--write", type=Path, default=None, metavar="FILE.msh", help="write the mesh (gmsh format)")


def face_distance_of(case):
    """The blocks' face distance when the case grades its mesh from them, else None."""
    if case.mesh.structure_band is None:
        return None
    from ..coupling.dem_side import shapes_of_blocks
    from ..dem.model import build_state, build_structure
    from ..fcm.levelset import FaceDistance
    state = build_state(case.dem, build_structure(case.dem))
    return FaceDistance(shapes_of_blocks(case.dem, state, case.coupling.min_thickness), state.pos, state.quat)


def run(args: argparse.Namespace) -> int:
    try:
        case = load_case(args.case, args.set)
        if case.mesh is None or case.mesh.kind not in ("gmsh_box", "gmsh_disk"):
            kind = None if case.mesh is None else case.mesh.kind
            raise ConfigError(f"{args.case}: key 'mesh.kind' = {kind!r}: this tool generates gmsh_box and gmsh_disk meshes")
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    import gmsh

    from ..mesh.build import generate_gmsh_box, longest_edges
    distance = face_distance_of(case)
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    t0 = time.perf_counter()
    generate_gmsh_box(case.mesh, distance)
    seconds = time.perf_counter() - t0
    dim = case.mesh.dim
    tags, coords, _ = gmsh.model.mesh.getNodes()
    x = np.zeros((int(tags.max()) + 1, 3))
    x[tags.astype(np.int64)] = coords.reshape(-1, 3)
    _, _, nodes = gmsh.model.mesh.getElements(dim)
    cells = np.concatenate(nodes).astype(np.int64).reshape(-1, dim + 1)
    h = longest_edges(x, cells)
    if args.write is not None:
        gmsh.write(str(args.write))
    gmsh.finalize()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    name = "tetrahedra" if dim == 3 else "triangles"
    print(f"{args.case}: {len(cells)} {name}, {len(tags)} vertices")
    print(f"longest edge per cell [m]: min {h.min():.4g}, median {np.median(h):.4g}, max {h.max():.4g}")
    print(f"generated in {seconds:.1f} s, peak memory {peak:.0f} MiB")
    if args.write is not None:
        print(f"written: {args.write}")
    return 0

