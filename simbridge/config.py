"""Validated configuration: YAML mappings into frozen dataclasses, with named, ranged errors.

A field is declared with `param(...)`, which records its unit, allowed range and meaning.
`build()` turns a YAML mapping into the dataclass and refuses, with one message naming the
file, the field and the allowed range, anything unknown, missing, mistyped or out of range.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml


class ConfigError(ValueError):
    """A configuration file or value is wrong; the message names file, field and range."""


def param(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    doc: str = "",
) -> Any:
    """A dataclass field with its unit, its allowed range [lo, hi] and a description."""
    meta = {"unit": unit, "lo": lo, "hi": hi, "lo_open": lo_open, "doc": doc}
    if isinstance(default, list | dict):
        frozen = tuple(default) if isinstance(default, list) else dict(default)
        return dataclasses.field(default_factory=lambda: frozen, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def range_text(f: dataclasses.Field) -> str:
    lo, hi, unit = f.metadata.get("lo"), f.metadata.get("hi"), f.metadata.get("unit", "")
    left = "(" if f.metadata.get("lo_open") else "["
    lo_s = "-inf" if lo is None else f"{lo:g}"
    hi_s = "inf" if hi is None else f"{hi:g}"
    return f"{left}{lo_s}, {hi_s}]" + (f" {unit}" if unit else "")


def _check_number(value: Any, f: dataclasses.Field, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{where}: expected a number in {range_text(f)}, got {value!r}")
    value = float(value)
    lo, hi = f.metadata.get("lo"), f.metadata.get("hi")
    bad = not math.isfinite(value)
    if lo is not None:
        bad |= value <= lo if f.metadata.get("lo_open") else value < lo
    if hi is not None:
        bad |= value > hi
    if bad:
        raise ConfigError(f"{where}: {value:g} is outside the allowed range {range_text(f)}")
    return value


def _convert(value: Any, hint: Any, f: dataclasses.Field, where: str) -> Any:
    origin = typing.get_origin(hint)
    if hint is float:
        return _check_number(value, f, where)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer in {range_text(f)}, got {value!r}")
        return int(_check_number(value, f, where))
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f, f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{where}: expected a list of {len(args)} values, got {value!r}")
        return tuple(
            _convert(v, a, f, f"{where}[{i}]")
            for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        return _convert(value, args[0], f, where)
    if dataclasses.is_dataclass(hint):
        return build(hint, value, where)
    raise ConfigError(f"{where}: unsupported field type {hint!r}")  # a programming error


def build(cls: type, mapping: Any, where: str) -> Any:
    """Build the frozen dataclass `cls` from a YAML mapping; `where` prefixes every message."""
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, Mapping):
        raise ConfigError(f"{where}: expected a mapping of fields, got {mapping!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        raise ConfigError(
            f"{where}: unknown field {unknown[0]!r}; known fields: {', '.join(sorted(fields))}"
        )
    values = {}
    for name, f in fields.items():
        sub = f"{where}.{name}"
        if name in mapping:
            values[name] = _convert(mapping[name], hints[name], f, sub)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{sub}: missing; allowed range {range_text(f)}")
    try:
        return cls(**values)
    except ConfigError:
        raise
    except ValueError as err:  # cross-field checks in __post_init__
        raise ConfigError(f"{where}: {err}") from None


def load_yaml(path: Path) -> dict[str, Any]:
    """Read a YAML mapping, turning every read or parse failure into a ConfigError."""
    try:
        text = Path(path).read_text()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read ({err.strerror})") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        at = f" at line {mark.line + 1}" if mark else ""
        raise ConfigError(f"{path}: not valid YAML{at}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping at the top level")
    return data


def resolve_packaged(name_or_path: str | Path, directory: Path, suffix: str, kind: str) -> Path:
    """A packaged file's name (`nano`, `rho2`, ...) in `directory`, or a path to a file."""
    path = Path(name_or_path)
    if path.suffix in (suffix, ".yml" if suffix == ".yaml" else suffix) or path.exists():
        return path
    packaged = directory / f"{name_or_path}{suffix}"
    if not packaged.exists():
        known = ", ".join(sorted(p.stem for p in directory.glob(f"*{suffix}")))
        raise ConfigError(f"{kind} {name_or_path!r}: no such file or packaged {kind} ({known})")
    return packaged
