"""Field metadata for the case schema: unit, physical meaning and allowed range.

Every field of every section dataclass is declared with :func:`param`, so the
strict loader (``loader.py``) can check ranges and the documentation generator
(``docs.py``) can write ``docs/case-reference.md`` from the same source.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any


def param(default: Any = dataclasses.MISSING, *, unit: str = "-", doc: str,
          gt: float | None = None, ge: float | None = None,
          lt: float | None = None, le: float | None = None,
          default_factory: Any = dataclasses.MISSING) -> Any:
    """A dataclass field carrying unit, documentation and bounds.

    ``gt``/``ge``/``lt``/``le`` bound a number (or every entry of a tuple of numbers).
    """
    meta = {"unit": unit, "doc": doc, "gt": gt, "ge": ge, "lt": lt, "le": le}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def range_text(meta: dict) -> str:
    """Human text of a field's allowed range, e.g. ``(0, 1]`` or ``> 0``."""
    lo_open, hi_open = meta.get("gt") is not None, meta.get("lt") is not None
    lo = meta.get("gt") if lo_open else meta.get("ge")
    hi = meta.get("lt") if hi_open else meta.get("le")
    if lo is None and hi is None:
        return ""
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if lo is None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def in_range(value: float, meta: dict) -> bool:
    """True when ``value`` is finite and satisfies the field's bounds."""
    if not math.isfinite(value):
        return False
    if meta.get("gt") is not None and not value > meta["gt"]:
        return False
    if meta.get("ge") is not None and not value >= meta["ge"]:
        return False
    if meta.get("lt") is not None and not value < meta["lt"]:
        return False
    if meta.get("le") is not None and not value <= meta["le"]:
        return False
    return True
