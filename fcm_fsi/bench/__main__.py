"""Benchmarks (not tests): ``python -m fcm_fsi.bench NAME [options]``; NAME is a module here."""
from __future__ import annotations

import importlib
import pkgutil
import sys

from . import __path__ as _bench_path


def available() -> list[str]:
    return sorted(m.name for m in pkgutil.iter_modules(_bench_path) if not m.name.startswith("_"))


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "--list"):
        print("usage: python -m fcm_fsi.bench NAME [options]\navailable: " + ", ".join(available()))
        return 0
    name, rest = argv[0], argv[1:]
    if name not in available():
        print(f"error: unknown benchmark {name!r}; available: {', '.join(available())}", file=sys.stderr)
        return 2
    return int(importlib.import_module(f"{__package__}.{name}").run(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())
