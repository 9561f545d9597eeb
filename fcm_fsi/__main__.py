"""``python -m fcm_fsi COMMAND [options]``: see :mod:`fcm_fsi.cli`."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
