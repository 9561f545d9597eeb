"""``python -m fcm_fsi.bench``: the former name of ``python -m fcm_fsi bench`` (fcm_fsi/tools/bench.py)."""
import sys

from ..cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
