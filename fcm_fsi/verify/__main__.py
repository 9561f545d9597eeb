"""``python -m fcm_fsi.verify``: the former name of ``python -m fcm_fsi verify`` (fcm_fsi/tools/verify.py)."""
import sys

from ..cli import main

if __name__ == "__main__":
    sys.exit(main(["verify", *sys.argv[1:]]))
