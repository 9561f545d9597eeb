"""``python -m fcm_fsi.dem.load_factor``: the former name of ``python -m fcm_fsi load-factor``
(fcm_fsi/tools/load_factor.py, which also holds the pushover functions)."""
import sys

if __name__ == "__main__":
    from ..cli import main
    sys.exit(main(["load-factor", *sys.argv[1:]]))
