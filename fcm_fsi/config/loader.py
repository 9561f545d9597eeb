"""Strict YAML loading of frozen-dataclass schemas.

Bad input becomes one :class:`ConfigError` line that names the file, the key path,
the value and the allowed range — never a traceback from deep inside the solver.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

import yaml

from .fields import in_range, range_text


class ConfigError(ValueError):
    """A case file that cannot be accepted; the message is meant for the user."""


_MISSING = dataclasses.MISSING


def _is_optional(tp: Any) -> tuple[bool, Any]:
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(get_args(tp)) == 2:
            return True, args[0]
    return False, tp


def type_name(tp: Any) -> str:
    """Short user-facing name of a schema type."""
    optional, inner = _is_optional(tp)
    if optional:
        return f"{type_name(inner)} or null"
    origin = get_origin(tp)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {type_name(args[0])}"
        return f"list of {len(args)} {type_name(args[0])}"
    if origin is dict or tp is dict:
        return "mapping"
    if dataclasses.is_dataclass(tp):
        return "mapping"
    return {float: "number", int: "integer", bool: "true/false", str: "text"}.get(tp, str(tp))


class Variant(typing.NamedTuple):
    """A resolution variant being validated: its name and its own mapping (``resolutions.NAME``),
    so that an error in a value the variant sets names it as ``resolutions.NAME.key``."""

    name: str
    overlay: dict


def _set_by(overlay: dict, key: str) -> bool:
    """True when the dotted/indexed ``key`` (e.g. ``mesh.refine[0].size``) takes its value from
    ``overlay``: the variant sets it or a list or scalar above it (the merge replaces those)."""
    node: Any = overlay
    for part in re.split(r"\.|\[", key):
        if not isinstance(node, dict):
            return True
        part = part.rstrip("]")
        if part not in node:
            return False
        node = node[part]
    return True


class _Ctx:
    def __init__(self, source: str, variant: Variant | None = None):
        self.source = source
        self.variant = variant

    def fail(self, key: str, msg: str) -> typing.NoReturn:
        if key and self.variant is not None and _set_by(self.variant.overlay, key):
            key = f"resolutions.{self.variant.name}.{key}"
        where = f"key '{key}'" if key else "top level"
        raise ConfigError(f"{self.source}: {where}: {msg}")


def _convert(ctx: _Ctx, key: str, tp: Any, value: Any, meta: dict) -> Any:
    optional, inner = _is_optional(tp)
    if value is None:
        if optional:
            return None
        ctx.fail(key, f"is empty but must be {type_name(tp)}")
    tp = inner
    origin = get_origin(tp)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            ctx.fail(key, f"must be a mapping of keys, got {value!r}")
        return build(tp, value, ctx.source, prefix=key, variant=ctx.variant)
    if origin is Literal:
        choices = get_args(tp)
        if value not in choices:
            close = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            ctx.fail(key, f"= {value!r} is not allowed; choose one of "
                          f"{', '.join(repr(c) for c in choices)}{hint}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            ctx.fail(key, f"= {value!r} must be a {type_name(tp)}")
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            item_types = [args[0]] * len(value)
        else:
            if len(value) != len(args):
                ctx.fail(key, f"= {value!r} must have exactly {len(args)} entries")
            item_types = list(args)
        return tuple(_convert(ctx, f"{key}[{i}]", it, v, meta)
                     for i, (it, v) in enumerate(zip(item_types, value)))
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            ctx.fail(key, f"= {value!r} must be a mapping")
        for k, v in value.items():
            if not isinstance(v, (str, int, float, bool)) and v is not None:
                ctx.fail(f"{key}.{k}", f"= {v!r} must be a number, text, true/false or null")
            if isinstance(v, float) and not math.isfinite(v):
                ctx.fail(f"{key}.{k}", f"= {v!r} must be a finite number")
        return dict(value)
    if tp is bool:
        if not isinstance(value, bool):
            ctx.fail(key, f"= {value!r} must be true or false")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            ctx.fail(key, f"= {value!r} must be an integer"
                          + (f" in {range_text(meta)}" if range_text(meta) else ""))
        _check_range(ctx, key, value, meta)
        return value
    if tp is float:
        if isinstance(value, str):
            try:  # YAML 1.1 reads "1e-3" as text; accept plain numeric text.
                value = float(value)
            except ValueError:
                ctx.fail(key, f"= {value!r} must be a number"
                              + (f" in {range_text(meta)}" if range_text(meta) else "")
                              + (f" ({meta['unit']})" if meta.get("unit", "-") != "-" else ""))
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            ctx.fail(key, f"= {value!r} must be a number")
        _check_range(ctx, key, float(value), meta)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            ctx.fail(key, f"= {value!r} must be text")
        return value
    raise TypeError(f"schema type {tp!r} at {key} is not supported")  # programming error


def _check_range(ctx: _Ctx, key: str, value: float, meta: dict) -> None:
    if not in_range(value, meta):
        unit = meta.get("unit", "-")
        ctx.fail(key, f"= {value!r} is out of range: allowed {range_text(meta) or 'finite'}"
                      + (f" ({unit})" if unit != "-" else ""))


def build(cls: type, data: dict, source: str = "<case>", prefix: str = "",
          variant: Variant | None = None) -> Any:
    """Build dataclass ``cls`` from a mapping, strictly (unknown keys are errors). ``variant``:
    the resolution variant merged into ``data``, named in errors of the keys it sets."""
    ctx = _Ctx(source, variant)
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for k in data:
        if k not in fields:
            path = f"{prefix}.{k}" if prefix else str(k)
            close = difflib.get_close_matches(str(k), list(fields), n=1, cutoff=0.5)
            hint = f"; did you mean '{(prefix + '.') if prefix else ''}{close[0]}'?" if close else \
                f"; valid keys here: {', '.join(fields)}"
            ctx.fail(path, f"is not a known key{hint}")
    kwargs = {}
    for name, f in fields.items():
        path = f"{prefix}.{name}" if prefix else name
        if name in data:
            kwargs[name] = _convert(ctx, path, hints[name], data[name], dict(f.metadata))
        elif f.default is _MISSING and f.default_factory is _MISSING:
            ctx.fail(path, f"is required ({type_name(hints[name])}"
                           + (f", {f.metadata.get('unit')}" if f.metadata.get("unit", "-") != "-" else "")
                           + f": {f.metadata.get('doc', '')})")
    try:
        obj = cls(**kwargs)
    except ConfigError as err:  # cross-field checks raise with a bare message
        raise ConfigError(f"{source}: {err}") from None
    return obj


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping (PyYAML keeps the last
    silently, so a duplicated section would replace the first without a word)."""

    def construct_mapping(self, node, deep=False):
        seen: dict = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                first = seen.setdefault(key, key_node.start_mark.line + 1)
            except TypeError:           # an unhashable key: PyYAML reports it below
                continue
            if first != key_node.start_mark.line + 1:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} appears twice in one mapping (lines {first} and "
                    f"{key_node.start_mark.line + 1})", key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


def read_yaml(path: Path) -> dict:
    """Read a case file: a YAML mapping of sections in UTF-8 text. A missing, unreadable, binary,
    empty or otherwise malformed file is one ConfigError line naming the file and the problem."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{path}: is a directory, not a case file")
    if not path.is_file():
        raise ConfigError(f"{path}: case file not found")
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the case file ({err.strerror})") from None
    if b"\x00" in raw:
        raise ConfigError(f"{path}: is not a text file (it contains NUL bytes at offset {raw.index(0)}): "
                          "a case file is YAML text")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as err:
        line = raw[:err.start].count(b"\n") + 1
        raise ConfigError(f"{path}: line {line} is not UTF-8 text (byte 0x{raw[err.start]:02x} at offset "
                          f"{err.start}): save the case file as UTF-8") from None
    try:
        data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}:{where} is not valid YAML ({getattr(err, 'problem', None) or err})") from None
    except RecursionError:
        raise ConfigError(f"{path}: is not valid YAML (nested too deeply)") from None
    if data is None:
        raise ConfigError(f"{path}: is empty: a case file is a mapping of sections (name, run, mesh, …; "
                          "docs/case-reference.md)")
    if not isinstance(data, dict):
        kind = {list: "a list", str: "a single text", int: "a number", float: "a number", bool: "true/false"}.get(
            type(data), type(data).__name__)
        raise ConfigError(f"{path}: is {kind}, not a mapping: a case file is a mapping of sections "
                          "(name, run, mesh, …; docs/case-reference.md)")
    bad = [k for k in data if not isinstance(k, str)]
    if bad:
        raise ConfigError(f"{path}: top level: key {bad[0]!r} is not a name (section names are text)")
    return data


def apply_override(data: dict, assignment: str, source: str = "--set") -> None:
    """Apply ``key.path=value`` (value parsed as YAML) to a nested mapping in place."""
    if "=" not in assignment:
        raise ConfigError(f"{source} {assignment!r}: expected key.path=value")
    keypath, raw = assignment.split("=", 1)
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = raw
    node = data
    parts = keypath.strip().split(".")
    for part in parts[:-1]:
        if node.get(part) is None:
            node[part] = {}
        if not isinstance(node[part], dict):
            raise ConfigError(f"{source} {assignment!r}: '{part}' is not a section")
        node = node[part]
    node[parts[-1]] = value


def to_dict(obj: Any) -> Any:
    """Resolved configuration as plain YAML-ready data."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple):
        return [to_dict(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_dict(v) for k, v in obj.items()}
    return obj
