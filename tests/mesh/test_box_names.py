"""Boundary names by axis: every plane of a rectangle/box mesh is tagged ``xmin xmax ymin ymax``
(and ``zmin zmax`` in 3D), and a case naming a boundary by its former name (``left`` … ``back``)
is refused with the axis name."""
from __future__ import annotations

import re

import numpy as np
import pytest
import yaml
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fcm_fsi.config.case import case_from_dict, load_case
from fcm_fsi.config.loader import ConfigError
from fcm_fsi.config.mesh import box_boundary_names
from fcm_fsi.mesh.channel import box, rectangle

LOWER_3D, UPPER_3D = (-1.0, 0.5, 2.0), (3.0, 1.5, 4.0)
#: former name → its axis name (the same plane, in 2D and 3D)
RENAMED = {"left": "xmin", "right": "xmax", "bottom": "ymin", "top": "ymax", "front": "zmin", "back": "zmax"}


def plane_of_every_facet(tm, lower, upper) -> dict[str, tuple[int, float]]:
    """name → (axis, coordinate) of the one plane all of the name's facet midpoints lie in."""
    fdim = tm.mesh.topology.dim - 1
    planes = {}
    for name, tag in tm.names.items():
        facets = tm.facet_tags.find(tag)
        assert len(facets), name
        mid = dmesh.compute_midpoints(tm.mesh, fdim, facets)[:, :len(lower)]
        on = [(a, c) for a in range(len(lower)) for c in (lower[a], upper[a]) if np.allclose(mid[:, a], c)]
        assert len(on) == 1, (name, on)
        planes[name] = on[0]
    return planes


def test_rectangle_and_box_name_their_planes_by_axis():
    """Tags 1, 2, … are xmin, xmax, ymin, ymax (, zmin, zmax); each lies on its plane, e.g. xmax
    on x = upper[0] and zmin on z = lower[2]."""
    lower2, upper2 = (-1.0, 0.5), (3.0, 1.5)
    for tm, lower, upper in ((rectangle(MPI.COMM_SELF, lower2, upper2, (4, 2)), lower2, upper2),
                             (box(MPI.COMM_SELF, LOWER_3D, UPPER_3D, (2, 2, 2)), LOWER_3D, UPPER_3D)):
        dim = len(lower)
        assert tm.names == {n: i for i, n in enumerate(box_boundary_names(dim), 1)}
        expected = {f"{'xyz'[a]}{end}": (a, (lower, upper)[end == "max"][a])
                    for a in range(dim) for end in ("min", "max")}
        assert plane_of_every_facet(tm, lower, upper) == expected


def case_data(dim: int, boundary: str, kind: str | None = None) -> dict:
    mesh = {"kind": "rectangle", "lower": [0.0, 0.0], "upper": [1.0, 1.0], "cells": [4, 4]} if dim == 2 else \
        {"kind": "box", "lower": list(LOWER_3D), "upper": list(UPPER_3D), "cells": [2, 2, 2]}
    if kind is not None:
        mesh = {**mesh, "kind": kind, "file": "tank.msh"}
    return {"name": "names", "run": {"t_end": 1.0, "dt": 0.1}, "mesh": mesh,
            "fluid": {"boundaries": [{"boundary": "xmax", "kind": "slip"},
                                     {"boundary": boundary, "kind": "no_slip"}]}}


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("former", list(RENAMED))
def test_a_former_name_is_refused_with_its_axis_name(former, dim):
    new = RENAMED[former]
    if new in box_boundary_names(dim):
        message = f"key 'fluid.boundaries[1].boundary' = '{former}': boundaries are named by axis now; " \
                  f"in {dim}D '{former}' is '{new}'"
    else:               # front/back in 2D: no such plane
        message = f"'{former}' was the 3D '{new}', and a 2D mesh has xmin, xmax, ymin, ymax"
    with pytest.raises(ConfigError, match=re.escape(message)):
        case_from_dict(case_data(dim, former))


def test_the_error_names_the_case_file_and_the_resolution(tmp_path):
    """From a file: the file and the key; a resolution level that brings a former name back is
    named as well. gmsh_file meshes are tagged by the same planes (mesh.lower/upper), so the
    former names are refused there too."""
    path = tmp_path / "tank.yaml"
    path.write_text(yaml.safe_dump(case_data(3, "front")))
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: key 'fluid.boundaries\[1\].boundary' = 'front': .*'zmin'"):
        load_case(path)
    data = {**case_data(3, "zmin"), "resolution": "fine",
            "resolutions": {"fine": {"fluid": {"boundaries": [{"boundary": "back", "kind": "do_nothing"}]}}}}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=r"\[resolution 'fine'\].*'back' is 'zmax'"):
        load_case(path)
    with pytest.raises(ConfigError, match="'top' is 'ymax'"):
        case_from_dict(case_data(3, "top", kind="gmsh_file"))
    assert case_from_dict(case_data(3, "zmin", kind="gmsh_file")).fluid.boundaries[1].boundary == "zmin"
