"""Generate docs/case-reference.md from the schema, so the docs cannot drift from the code.

    python -m fcm_fsi.config.docs > docs/case-reference.md

The reference ends with the pre-run checks (``fcm_fsi.preflight.CHECKS``). They look at the
built geometry, so they live above config: the caller passes them in, and the command above
imports them only when run as a script.
"""
from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Sequence
from typing import get_type_hints

from .case import RESOLUTION_DOC, Case
from .fields import range_text
from .loader import _is_optional, type_name


def _section_types(tp) -> list[type]:
    """Dataclass types reachable from a field type (optional, tuples of dataclasses)."""
    _, inner = _is_optional(tp)
    if dataclasses.is_dataclass(inner):
        return [inner]
    args = getattr(inner, "__args__", ()) or ()
    return [a for a in args if dataclasses.is_dataclass(a)]


def _default_text(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        return "`null`" if f.default is None else f"`{f.default!r}`"
    if f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
        return "—" if dataclasses.is_dataclass(value) else f"`{value!r}`"
    return "**required**"


def reference_markdown(checks: Sequence[Callable]) -> str:
    """The case-file reference: every section of the schema, then the pre-run ``checks``."""
    lines = ["# Case-file reference", "",
             "Generated from the schema by `python -m fcm_fsi.config.docs > docs/case-reference.md`;",
             "a test fails when this file is stale. Units are SI. Unknown keys are errors.", "",
             RESOLUTION_DOC, ""]
    seen: set[type] = set()
    queue: list[tuple[str, type]] = [("(top level)", Case)]
    while queue:
        path, cls = queue.pop(0)
        if cls in seen:
            continue
        seen.add(cls)
        hints = get_type_hints(cls)
        lines += [f"## `{path}` — {cls.__name__}", "", (cls.__doc__ or "").strip().split("\n\n")[0], "",
                  "| key | type | unit | default | allowed | meaning |", "|---|---|---|---|---|---|"]
        for f in dataclasses.fields(cls):
            meta = f.metadata
            doc = meta.get("doc", "").replace("|", "\\|")
            lines.append(f"| `{f.name}` | {type_name(hints[f.name])} | {meta.get('unit', '-')} | "
                         f"{_default_text(f)} | {range_text(meta)} | {doc} |")
            for sub in _section_types(hints[f.name]):
                queue.append((f.name if path == "(top level)" else f"{path}.{f.name}", sub))
        lines.append("")
    return "\n".join(lines + checks_markdown(checks))


def checks_markdown(checks: Sequence[Callable]) -> list[str]:
    """The pre-run checks (``fcm_fsi.preflight.CHECKS``: every run and ``--validate``), one line
    each, from their docstrings."""
    lines = ["## Pre-run checks", "",
             "Run before anything is built, by every run and by `--validate` (`fcm_fsi/preflight.py`). "
             "An error stops with exit code 2 and one line naming the key; a warning is logged and the run "
             "goes on. Every resolution level is validated against the schema; these checks apply to the "
             "chosen one.", ""]
    for check in checks:
        doc = " ".join((check.__doc__ or "").split())
        lines.append(f"- `{check.__name__}`: {doc}")
    lines.append("")
    return lines


if __name__ == "__main__":
    from ..preflight import CHECKS
    sys.stdout.write(reference_markdown(CHECKS))
