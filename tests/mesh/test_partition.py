"""The mesh partition is the same in every run of a case on the same ranks (``import fcm_fsi``
sets one PT-Scotch thread): with PT-Scotch's default threads it was not, and a 2-rank run's
results then differed from run to run at round-off from the first step on."""
import shutil
import subprocess
import sys

import pytest

from tests.conftest import ROOT, mpi_env

SCRIPT = """
import hashlib, numpy as np
from mpi4py import MPI
from fcm_fsi.config.case import load_case
from fcm_fsi.mesh.build import build_mesh
msh = build_mesh(load_case("cases/tsunami_building.yaml").mesh, MPI.COMM_WORLD)
x = msh.geometry.x[: msh.geometry.index_map().size_local]
mine = (msh.topology.index_map(3).size_local, hashlib.sha1(x.tobytes()).hexdigest())
parts = MPI.COMM_WORLD.gather(mine)
if MPI.COMM_WORLD.rank == 0:
    print("PARTS", parts, flush=True)
"""


@pytest.mark.mpi
def test_two_rank_partition_is_the_same_in_every_run():
    env = mpi_env()
    env.pop("SCOTCH_PTHREAD_NUMBER", None)
    runs = []
    for _ in range(3):
        out = subprocess.run([shutil.which("mpirun"), "-n", "2", sys.executable, "-c", SCRIPT], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr[-2000:]
        runs.append([line for line in out.stdout.splitlines() if line.startswith("PARTS")])
    assert len(runs[0]) == 1
    assert runs[1] == runs[0] and runs[2] == runs[0]
