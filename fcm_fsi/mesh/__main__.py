"""``python -m fcm_fsi.mesh``: the former name of ``python -m fcm_fsi mesh`` (fcm_fsi/tools/mesh.py)."""
import sys

from ..cli import main

if __name__ == "__main__":
    sys.exit(main(["mesh", *sys.argv[1:]]))
