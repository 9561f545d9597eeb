#!/usr/bin/env bash
# One-command set-up on Debian 12 (bookworm), as root or as a user who may sudo (only the
# Debian packages need root; the virtual environment belongs to whoever runs this):
#   Debian packages for dolfinx 0.5.2 + PETSc + MPI + Numba, then a virtual environment
#   .venv made from /usr/bin/python3 with --system-site-packages (so it sees dolfinx),
#   with fcm_fsi installed in editable mode, and the linter ruff (pinned, from PyPI).
#   libopenblas0-serial replaces the reference BLAS under MUMPS and NumPy (3.2x faster LU,
#   docs/performance.md); serial because the MPI ranks are the parallelism.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
PKGS="python3-dolfinx-real python3-petsc4py python3-mpi4py python3-gmsh python3-numba
      python3-meshio python3-h5py python3-yaml python3-scipy python3-matplotlib python3-pytest
      python3-venv python3-setuptools python3-pip openmpi-bin libopenblas0-serial"
missing=$(dpkg-query -W -f='${Package} ${Status}\n' $PKGS 2>/dev/null | grep -vc 'install ok installed' || true)
if [ "$missing" != "0" ] || ! dpkg-query -W $PKGS >/dev/null 2>&1; then
  as_root=()
  if [ "$(id -u)" != "0" ]; then
    command -v sudo >/dev/null || { echo "setup: the Debian packages need root, and sudo is not installed:" \
                                         "run this as root" >&2; exit 1; }
    as_root=(sudo env DEBIAN_FRONTEND=noninteractive)
  fi
  "${as_root[@]}" apt-get update -qq
  "${as_root[@]}" apt-get install -y -qq --no-install-recommends $PKGS >/dev/null
fi
if [ ! -x .venv/bin/python ]; then
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
.venv/bin/python -m pip install -q --no-deps --no-build-isolation -e .
# ruff (the linter .ci/run runs before the tests) is not a Debian bookworm package: the pinned
# wheel from PyPI, one static binary with no dependencies.
.venv/bin/python -m pip install -q "ruff==0.17.6"
.venv/bin/python -c "import dolfinx, numba, fcm_fsi; print('fcm_fsi set up: dolfinx', dolfinx.__version__, 'numba', numba.__version__)"
