"""``python -m fcm_fsi.mesh``: the former name of ``python -m fcm_fsi mesh`` (fcm_fsi/tools/mesh.py)."""
import sys

if __name__ == "__main__":
    from ..cli import main
    sys.exit(main(["mesh", *sys.argv[1:]]))
