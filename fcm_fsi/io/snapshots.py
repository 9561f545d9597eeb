"""``python -m fcm_fsi.io.snapshots``: the former name of ``python -m fcm_fsi snapshots``
(fcm_fsi/tools/snapshots.py, which also holds the rendering functions)."""
import sys

if __name__ == "__main__":
    from ..cli import main
    sys.exit(main(["snapshots", *sys.argv[1:]]))
