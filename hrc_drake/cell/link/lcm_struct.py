"""LCM types made from their definitions in LCM syntax, with no code generator: the base class
`LcmStruct` encodes, decodes and fingerprints a struct from its members (`Field`s) exactly as the
Python code lcm-gen writes for the same definition does, and `parse_definitions` turns LCM text
into such classes.

Apart from the cell's messages (`hrc_drake.cell.link.lcm_messages`) because it knows nothing of
the cell: it is LCM's wire format (big-endian members after an 8-byte fingerprint, lcm-gen's
hash), which a driver built with lcm-gen must read unchanged. A message of another type or
definition fails to decode with `LcmDecodeError`, naming both fingerprints.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from io import BytesIO
from typing import ClassVar

_PRIMITIVES = {
    "int8_t": "b",
    "int16_t": "h",
    "int32_t": "i",
    "int64_t": "q",
    "byte": "B",
    "float": "f",
    "double": "d",
    "boolean": "b",
}
_DEFAULTS = {"float": 0.0, "double": 0.0, "boolean": False, "string": ""}
_MASK = (1 << 64) - 1
_FINGERPRINTS: dict[type, bytes] = {}


class LcmDecodeError(ValueError):
    """Bytes that are not a message of the expected type."""


@dataclass(frozen=True)
class Field:
    """A member of an LCM struct: its type (a primitive name or a struct class), its name, and
    its dimensions (a number for a fixed size, the name of an earlier member for a variable
    one)."""

    type: str | type
    name: str
    dims: tuple[int | str, ...] = ()


def _hash_update(v: int, c: int) -> int:
    """lcm-gen's hash step on a signed 64-bit value (`c` is a C `char`)."""
    c = (c + 128) % 256 - 128
    v = ((v << 8) ^ (v >> 55)) + c
    v &= _MASK
    return v - (1 << 64) if v >> 63 else v


def _hash_string(v: int, text: str) -> int:
    v = _hash_update(v, len(text))
    for byte in text.encode():
        v = _hash_update(v, byte)
    return v


def struct_hash(fields: Sequence[Field]) -> int:
    """lcm-gen's hash of a struct's members (`lcm_struct_hash`): names, primitive types and
    dimensions; the struct's own name does not count, nor the members' struct types (their
    own hashes are added by `_get_hash_recursive`)."""
    v = 0x12345678
    for f in fields:
        v = _hash_string(v, f.name)
        if isinstance(f.type, str):
            v = _hash_string(v, f.type)
        v = _hash_update(v, len(f.dims))
        for d in f.dims:
            v = _hash_update(v, 0 if isinstance(d, int) else 1)  # LCM_CONST, LCM_VAR
            v = _hash_string(v, str(d))
    return v & _MASK


class LcmStruct:
    """Base of our LCM types: encode/decode and the fingerprint from `FIELDS`, as lcm-gen's
    Python code does for the same definition."""

    FIELDS: ClassVar[tuple[Field, ...]] = ()
    __slots__ = ()

    def __init__(self, **values):
        for f in self.FIELDS:
            value = values.pop(f.name) if f.name in values else self._default(f, 0)
            setattr(self, f.name, value)
        if values:
            raise TypeError(f"{type(self).__name__} has no members {sorted(values)}")

    @classmethod
    def _default(cls, f: Field, depth: int):
        if depth < len(f.dims):
            size = f.dims[depth]
            n = size if isinstance(size, int) else 0
            return [cls._default(f, depth + 1) for _ in range(n)]
        if isinstance(f.type, type):
            return f.type()
        return _DEFAULTS.get(f.type, 0)

    def __eq__(self, other) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(getattr(self, f.name) == getattr(other, f.name) for f in self.FIELDS)

    def __repr__(self) -> str:
        members = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in self.FIELDS)
        return f"{type(self).__name__}({members})"

    @classmethod
    def _get_hash_recursive(cls, parents: list) -> int:
        if cls in parents:
            return 0
        parents = [*parents, cls]
        children = sum(f.type._get_hash_recursive(parents) for f in cls.FIELDS if _is_struct(f))
        h = (struct_hash(cls.FIELDS) + children) & _MASK
        return ((h << 1) & _MASK) + (h >> 63)

    @classmethod
    def _get_packed_fingerprint(cls) -> bytes:
        if cls not in _FINGERPRINTS:  # computed once per type, as lcm-gen's code does
            _FINGERPRINTS[cls] = struct.pack(">Q", cls._get_hash_recursive([]))
        return _FINGERPRINTS[cls]

    def encode(self) -> bytes:
        """The message as LCM bytes (fingerprint, then the members)."""
        buf = BytesIO()
        buf.write(self._get_packed_fingerprint())
        self._encode_one(buf)
        return buf.getvalue()

    def _encode_one(self, buf: BytesIO) -> None:
        for f in self.FIELDS:
            sizes = [d if isinstance(d, int) else getattr(self, d) for d in f.dims]
            _encode_value(buf, f.type, sizes, getattr(self, f.name))

    @classmethod
    def decode(cls, data: bytes):
        """The message in `data`; LcmDecodeError if it is not one of this type."""
        buf = BytesIO(data)
        fingerprint, expected = buf.read(8), cls._get_packed_fingerprint()
        if fingerprint != expected:
            raise LcmDecodeError(
                f"not a {cls.__name__} message: fingerprint {fingerprint.hex() or 'none'}, "
                f"{cls.__name__} has {expected.hex()}; both sides must use the same message "
                "definitions (the same hrc_drake version)"
            )
        try:
            return cls._decode_one(buf)
        except (struct.error, UnicodeDecodeError) as err:
            raise LcmDecodeError(f"a truncated or garbled {cls.__name__} message: {err}") from None

    @classmethod
    def _decode_one(cls, buf: BytesIO):
        message = cls.__new__(cls)
        for f in cls.FIELDS:
            sizes = [d if isinstance(d, int) else getattr(message, d) for d in f.dims]
            setattr(message, f.name, _decode_value(buf, f.type, sizes))
        return message

    @classmethod
    def definition(cls) -> str:
        """The struct in LCM syntax (for lcm-gen)."""
        lines = [f"struct {cls.__name__} {{"]
        for f in cls.FIELDS:
            kind = f.type if isinstance(f.type, str) else f.type.__name__
            lines.append(f"    {kind} {f.name}{''.join(f'[{d}]' for d in f.dims)};")
        return "\n".join([*lines, "}"])


def _is_struct(f: Field) -> bool:
    return isinstance(f.type, type)


def _encode_value(buf: BytesIO, kind, sizes: list[int], value) -> None:
    if sizes:
        items = list(value)[: sizes[0]]
        if len(items) != sizes[0]:
            raise ValueError(f"array of {len(items)} items where {sizes[0]} are declared")
        if len(sizes) == 1 and kind in _PRIMITIVES:
            buf.write(struct.pack(f">{sizes[0]}{_PRIMITIVES[kind]}", *items))
            return
        for item in items:
            _encode_value(buf, kind, sizes[1:], item)
    elif isinstance(kind, type):
        value._encode_one(buf)
    elif kind == "string":
        text = value.encode("utf-8")
        buf.write(struct.pack(">I", len(text) + 1) + text + b"\0")
    else:
        buf.write(struct.pack(f">{_PRIMITIVES[kind]}", value))


def _decode_value(buf: BytesIO, kind, sizes: list[int]):
    if sizes:
        if len(sizes) == 1 and kind in _PRIMITIVES:
            code = _PRIMITIVES[kind]
            values = struct.unpack(f">{sizes[0]}{code}", buf.read(sizes[0] * struct.calcsize(code)))
            return [bool(v) for v in values] if kind == "boolean" else list(values)
        return [_decode_value(buf, kind, sizes[1:]) for _ in range(sizes[0])]
    if isinstance(kind, type):
        return kind._decode_one(buf)
    if kind == "string":
        (length,) = struct.unpack(">I", buf.read(4))
        return buf.read(length)[:-1].decode("utf-8")
    code = _PRIMITIVES[kind]
    (value,) = struct.unpack(f">{code}", buf.read(struct.calcsize(code)))
    return bool(value) if kind == "boolean" else value


_MEMBER = re.compile(r"^(\w+)\s+(\w+)((?:\s*\[\s*\w+\s*\])*)$")


def parse_definitions(text: str, module: str) -> dict[str, type]:
    """The structs of `text` in LCM syntax as `LcmStruct` classes by name (a member's struct type
    must be defined before it); `module` is where they are kept (their `__module__`, so that
    they pickle by name)."""
    text = re.sub(r"//[^\n]*", "", text)
    types: dict[str, type] = {}
    for name, body in re.findall(r"struct\s+(\w+)\s*\{([^}]*)\}", text):
        fields = []
        for statement in filter(None, (s.strip() for s in body.split(";"))):
            match = _MEMBER.match(" ".join(statement.split()))
            if match is None:
                raise ValueError(f"struct {name}: cannot read the member {statement!r}")
            kind, member, dims = match.groups()
            sizes = tuple(int(d) if d.isdigit() else d for d in re.findall(r"\w+", dims))
            fields.append(Field(types.get(kind, kind), member, sizes))
        slots = tuple(f.name for f in fields)
        members = {"FIELDS": tuple(fields), "__slots__": slots, "__module__": module}
        types[name] = type(name, (LcmStruct,), members)
    return types
