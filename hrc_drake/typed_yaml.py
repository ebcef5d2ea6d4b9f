"""Strict, typed YAML loading into dataclasses, without Drake.

Scenarios are read with `load_typed` here (`hrc_drake.scenario.load`), as Drake's
`yaml_load_typed` reads them (a test holds the two together), without importing Drake, so that
the task layer can read them too. Both are strict in the same way: an unknown key or a value
of the wrong type is an error naming the key, and keys left out keep the schema's defaults (or
those of `defaults`, for command-line overrides on top of a file).

Supported field types: `str`, `int`, `float` (an int is accepted), `bool`, `X | None`, `X | Y`
(the first that fits), `list[X]`, `dict[str, X]` and nested dataclasses. A union of dataclasses
(`GripLost | NoSeat | ...`) holds tagged variants, as Drake's loader reads them: the YAML tag
`!Name` chooses the member whose class is named Name (`!GripLost {task: 2}`). Stricter than
Drake, which reads an untagged mapping as the first member: here it is an error naming the key
and the tags to choose from.
"""

from __future__ import annotations

import dataclasses
import difflib
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


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping: YAML forbids it, and
    PyYAML would keep the last value silently (a careless `{hold_time: 1, hold_time: 5}`)."""

    def construct_mapping(self, node, deep=False):
        """The mapping of `node`; ConstructorError at the second occurrence of a key."""
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # `<<: *base` may be overridden key by key, as YAML intends
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:
                    continue  # an unhashable key is refused by the base class below
                if duplicate:
                    raise yaml.constructor.ConstructorError(
                        "while constructing a mapping",
                        node.start_mark,
                        f"found duplicate key {key!r}; give each key once",
                        key_node.start_mark,
                    )
                seen.add(key)
        return super().construct_mapping(node, deep=deep)


def safe_load_unique(text: str) -> Any:
    """`yaml.safe_load(text)`, but a key given twice in a mapping is a yaml.YAMLError (with its
    line and column, for `yaml_error_line`) instead of the last value winning silently."""
    return yaml.load(text, Loader=_UniqueKeyLoader)  # a SafeLoader subclass: as safe


@dataclasses.dataclass(frozen=True)
class Tagged:
    """A YAML node with a local tag, `!Name {...}`: the tag's name (without the `!`) and the
    node's value (a mapping, for a variant). Only a union of dataclasses takes one."""

    name: str
    value: Any


class _TaggedLoader(_UniqueKeyLoader):
    """`_UniqueKeyLoader` reading a node with a local tag (`!GripLost {task: 2}`) as a `Tagged`
    value, for a union of dataclasses to choose its member by (as Drake's loader does). Still
    a SafeLoader: a tag builds no object but that small value; YAML's own `!!` tags are
    unchanged."""


def _construct_tagged(loader: _TaggedLoader, name: str, node: yaml.Node) -> Tagged:
    if isinstance(node, yaml.MappingNode):
        return Tagged(name, loader.construct_mapping(node, deep=True))
    if isinstance(node, yaml.SequenceNode):
        return Tagged(name, loader.construct_sequence(node, deep=True))
    return Tagged(name, loader.construct_scalar(node))


_TaggedLoader.add_multi_constructor("!", _construct_tagged)


class _TaggedDumper(yaml.SafeDumper):
    """PyYAML's safe dumper, writing a `Tagged` value back as the tagged node it was read
    from."""


def _represent_tagged(dumper: _TaggedDumper, tagged: Tagged) -> yaml.Node:
    tag = f"!{tagged.name}"
    if isinstance(tagged.value, dict):
        return dumper.represent_mapping(tag, tagged.value)
    if isinstance(tagged.value, list):
        return dumper.represent_sequence(tag, tagged.value)
    return dumper.represent_scalar(tag, str(tagged.value))


_TaggedDumper.add_representer(Tagged, _represent_tagged)


def load_tagged(text: str) -> Any:
    """`safe_load_unique(text)` that keeps local tags (`!GripLost {task: 2}`), for a typed
    schema's variants (`load_typed`) or to write the text out again (`dump_flow`); any other
    tag is still a yaml.YAMLError."""
    return yaml.load(text, Loader=_TaggedLoader)  # a SafeLoader subclass: as safe


def dump_flow(data: Any) -> str:
    """`data` (as `load_tagged` reads it) as one line of YAML flow text, keys in their order and
    tags kept: `{faults: [!GripLost {task: 2}]}`."""
    return yaml.dump(
        data, Dumper=_TaggedDumper, default_flow_style=True, width=10**6, sort_keys=False
    ).strip()


def _short(value: Any, limit: int = 60) -> str:
    """`repr(value)`, cut to `limit` characters: a whole text file read as one YAML string
    (`--scenario README.md`) must not fill the terminal with a one-line error."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 5]}...{text[-1]}"


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


def _variants(tp: Any) -> list[type]:
    """The members of `tp` when it is a union of two or more dataclasses (tagged variants),
    else []. `X | None` with one dataclass X is an optional section, not a variant."""
    if typing.get_origin(tp) not in (typing.Union, types.UnionType):
        return []
    inner = [a for a in typing.get_args(tp) if a is not type(None)]
    return inner if len(inner) > 1 and all(map(dataclasses.is_dataclass, inner)) else []


def _tags(members: list[type]) -> str:
    return ", ".join(f"!{m.__name__}" for m in members)


def _flow(mapping: dict, limit: int = 60) -> str:
    """`mapping` as short YAML flow text, for an example in a message."""
    text = dump_flow(mapping)
    return text if len(text) <= limit else "{...}"


def _untagged(value: Any, members: list[type]) -> str:
    """What is wrong with an untagged `value` where a variant of `members` goes, and the fix.
    A mapping with a `kind:` naming a member's `kind` (a class attribute, e.g. FaultKind's
    `grip-lost`) is written with that member's tag instead."""
    first = members[0].__name__
    if not isinstance(value, dict):
        return f"expected a tagged mapping, e.g. !{first} {{...}}, got {_short(value)}"
    if "kind" not in value:
        return f"untagged {_flow(value)}: tag it with its type, e.g. !{first} {_flow(value)}"
    rest = {k: v for k, v in value.items() if k != "kind"}
    kinds = {m: getattr(m, "kind", None) for m in members}
    named = [m for m, kind in kinds.items() if kind is not None and str(kind) == str(value["kind"])]
    if named:
        return f"the kind is a tag, not a key: write !{named[0].__name__} {_flow(rest)}"
    return (
        f"the kind is a tag, not a key (and {_short(value['kind'])} is none): write e.g. "
        f"!{first} {_flow(rest)}"
    )


def _variant(value: Any, members: list[type], key: str, default: Any) -> Any:
    """The member of a union of dataclasses that the YAML tag `!Name` names (the class's
    `__name__`), read from the tagged mapping as that dataclass (merged onto `default` when it
    is already of that member, as Drake merges)."""
    if not isinstance(value, Tagged):
        raise TypedYamlError(f"{key}: {_untagged(value, members)}; the tags are {_tags(members)}")
    chosen = next((m for m in members if m.__name__ == value.name), None)
    if chosen is None:
        close = difflib.get_close_matches(value.name, [m.__name__ for m in members], n=1)
        hint = f" (did you mean !{close[0]}?)" if close else ""
        raise TypedYamlError(
            f"{key}: unknown tag !{value.name}{hint}; the tags are {_tags(members)}"
        )
    if value.value == "":  # `rg2: !Simulated` alone, which Drake's loader refuses too
        raise TypedYamlError(
            f"{key}: !{value.name} takes a mapping, even an empty one: write !{value.name} {{}}"
        )
    base = default if isinstance(default, chosen) else None
    return _merge(value.value, chosen, key, base)


def _convert(value: Any, tp: Any, key: str, default: Any = dataclasses.MISSING) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    members = _variants(tp)
    if members and not (value is None and type(None) in args):
        return _variant(value, members, key, default)
    if isinstance(value, Tagged):
        raise TypedYamlError(
            f"{key}: a tag (!{value.name}) chooses among variants; {key} has none: leave it out"
        )
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        # `float | str` (as Drake's loader reads it): the first type the value fits.
        mapped = None  # a mapping's error as a dataclass member: it names the key at fault
        for tp_ in inner[:-1]:
            try:
                return _convert(value, tp_, key, default)
            except TypedYamlError as err:
                if mapped is None and isinstance(value, dict) and dataclasses.is_dataclass(tp_):
                    mapped = err
        try:
            return _convert(value, inner[-1], key, default)
        except TypedYamlError:
            if mapped is not None:
                raise mapped from None
            raise
    if dataclasses.is_dataclass(tp):
        base = default if dataclasses.is_dataclass(default) else None
        return _merge(value, tp, key, base)
    if origin is list:
        if not isinstance(value, list):
            raise TypedYamlError(f"{key}: expected a list, got {_short(value)}")
        return [_convert(v, args[0], f"{key}[{i}]") for i, v in enumerate(value)]
    if origin is dict:
        if not isinstance(value, dict):
            raise TypedYamlError(f"{key}: expected a mapping, got {_short(value)}")
        return {str(k): _convert(v, args[1], f"{key}.{k}") for k, v in value.items()}
    if tp is float:
        if isinstance(value, str) and _EXPONENT_NUMBER.match(value.strip()):
            return float(value)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise TypedYamlError(f"{key}: expected a number, got {_short(value)}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise TypedYamlError(f"{key}: expected a whole number, got {_short(value)}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise TypedYamlError(f"{key}: expected true or false, got {_short(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise TypedYamlError(f"{key}: expected a string, got {_short(value)} (quote it)")
        return value
    raise TypeError(f"typed_yaml: unsupported field type {tp!r} at {key}")


def _merge(data: Any, schema: type, where: str, base: Any = None) -> Any:
    prefix = f"{where}." if where else ""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise TypedYamlError(f"{where or '<top>'}: expected a mapping, got {_short(data)}")
    hints = typing.get_type_hints(schema)
    # A field marked `metadata={"yaml": False}` is filled by the loader, never by the YAML.
    fields = {f.name: f for f in dataclasses.fields(schema) if f.metadata.get("yaml", True)}
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
    TypedYamlError naming `source` (a file name), the line and the column; so is a key given
    twice in one mapping (`safe_load_unique`).
    """
    if text is not None:
        try:
            data = load_tagged(text)
        except yaml.YAMLError as err:
            raise YamlSyntaxError(yaml_error_line(err, source)) from None
    base = dataclasses.replace(defaults) if defaults is not None else None
    return _merge(data, schema, "", base)
