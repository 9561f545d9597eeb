"""Strict YAML loading of frozen-dataclass schemas.

Bad input becomes one :class:`ConfigError` line that names the file, the key path,
the value and the allowed range — never a traceback from deep inside the solver.
"""
from __future__ import annotations

import dataclasses
import difflib
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


class _Ctx:
    def __init__(self, source: str):
        self.source = source

    def fail(self, key: str, msg: str) -> typing.NoReturn:
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
        return build(tp, value, ctx.source, prefix=key)
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


def build(cls: type, data: dict, source: str = "<case>", prefix: str = "") -> Any:
    """Build dataclass ``cls`` from a mapping, strictly (unknown keys are errors)."""
    ctx = _Ctx(source)
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


def read_yaml(path: Path) -> dict:
    """Read a YAML mapping; a missing or malformed file is a one-line ConfigError."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: case file not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}:{where} is not valid YAML ({getattr(err, 'problem', err)})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a case file must be a mapping of sections")
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
