"""Strict, typed YAML loading into dataclasses, without Drake.

The cell layer loads scenarios with Drake's `yaml_load_typed`; the task layer (which imports no
Drake) reads the same files with `load_typed` here. Both are strict in the same way: an unknown
key or a value of the wrong type is an error naming the key, and keys left out keep the schema's
defaults (or those of `defaults`, for command-line overrides on top of a file).

Supported field types: `str`, `int`, `float` (an int is accepted), `bool`, `X | None`,
`list[X]`, `dict[str, X]` and nested dataclasses.
"""

from __future__ import annotations

import dataclasses
import re
import types
import typing
from typing import Any

import yaml


class TypedYamlError(ValueError):
    """YAML that does not fit its schema; the message names the key."""


class YamlSyntaxError(TypedYamlError):
    """Text that is not YAML; the message names the source, the line and the column."""


# A number PyYAML (YAML 1.1) reads as a string because it has no dot, e.g. 5e-3; YAML 1.2 and
# Drake's yaml_load_typed read it as a number, so it is one here too.
_EXPONENT_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def yaml_error_line(err: yaml.YAMLError, source: str) -> str:
    """PyYAML's several-line message as one line naming `source`, the line and the column:
    ``flange.yaml, line 3, column 6: bad YAML: expected ',' or '}', but got ':' (while parsing a
    flow mapping from line 2, column 7)``."""
    mark = getattr(err, "problem_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    where = source if mark is None else f"{source}, line {mark.line + 1}, column {mark.column + 1}"
    context = getattr(err, "context", None)
    context_mark = getattr(err, "context_mark", None)
    if context and context_mark is not None:
        context = f"{context} from line {context_mark.line + 1}, column {context_mark.column + 1}"
    extra = f" ({context})" if context else ""
    return f"{where}: bad YAML: {problem}{extra}"


def _convert(value: Any, tp: Any, key: str, default: Any = dataclasses.MISSING) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _convert(value, inner, key, default)
    if dataclasses.is_dataclass(tp):
        base = default if dataclasses.is_dataclass(default) else None
        return _merge(value, tp, key, base)
    if origin is list:
        if not isinstance(value, list):
            raise TypedYamlError(f"{key}: expected a list, got {value!r}")
        return [_convert(v, args[0], f"{key}[{i}]") for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise TypedYamlError(f"{key}: expected a mapping, got {value!r}")
        return {str(k): _convert(v, args[1], f"{key}.{k}") for k, v in value.items()}
    if tp is float:
        if isinstance(value, str) and _EXPONENT_NUMBER.match(value.strip()):
            return float(value)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise TypedYamlError(f"{key}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypedYamlError(f"{key}: expected a whole number, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise TypedYamlError(f"{key}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise TypedYamlError(f"{key}: expected a string, got {value!r} (quote it)")
        return value
    raise TypeError(f"typed_yaml: unsupported field type {tp!r} at {key}")


def _merge(data: Any, schema: type, where: str, base: Any = None) -> Any:
    prefix = f"{where}." if where else ""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise TypedYamlError(f"{where or '<top>'}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(schema)
    fields = {f.name: f for f in dataclasses.fields(schema)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise TypedYamlError(
            f"{prefix}{unknown[0]}: unknown key; the keys of {where or 'the file'} are "
            f"{sorted(fields)}"
        )
    obj = dataclasses.replace(base) if base is not None else schema()
    for name, value in data.items():
        current = getattr(obj, name)
        setattr(obj, name, _convert(value, hints[name], f"{prefix}{name}", current))
    return obj


def load_typed(
    schema: type,
    *,
    text: str | None = None,
    data: Any = None,
    defaults: Any = None,
    source: str = "YAML",
):
    """An instance of the dataclass `schema` from YAML `text` (or parsed `data`).

    Keys missing from the YAML keep the values of `defaults` (an instance of `schema`) or the
    schema's own defaults; nested mappings merge key by key. A syntax error in `text` is a
    TypedYamlError naming `source` (a file name), the line and the column.
    """
    if text is not None:
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise YamlSyntaxError(yaml_error_line(err, source)) from None
    base = dataclasses.replace(defaults) if defaults is not None else None
    return _merge(data, schema, "", base)
