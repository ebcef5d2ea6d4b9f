"""Which scenario a process runs, told to the other side of the station link and compared.

`hrc-drake station` and `hrc-drake simulate --station-lcm` are started separately, each with its
own scenario options; nothing but the lockstep joins them. Before the first step they exchange a
`ScenarioIdentity` (`hrc_drake.cell.link.lockstep`, the session's "hello") and refuse to run when
the two differ: a controller of one scenario against the station of another would run to the end and
report the controller's scenario with the station's states.

An identity is the scenario's name, the command-line options that changed it (for the message
only), a digest of the assembly spec (its parsed YAML: comments and layout do not count), and the
scenario's resolved settings with their digest. What only the controller reads is left out, so
that it may differ between the two: the policy (or decider), the safety (separation) settings
and the interaction mode (the station's simulated operator reads only the interface's delay);
and so are the labels that change nothing (description, expected sequences, Table 2 row).
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from hrc_drake.hri.faults import FaultConfig
from hrc_drake.scenario.schema import Scenario

# Settings the station never reads, or that are labels only (dotted keys and their sub-keys).
NOT_COMPARED = (
    "description",
    "expected",
    "table2_row",
    "policy",
    "decider",  # proposes instead of the policy: the controller's too
    "safety",
    "interaction.mode",
)
SHOWN = 3  # differences named in a refusal; the rest are counted


def _plain(value):
    """`value` as JSON's types (dataclasses and mappings as dicts, sequences as lists)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        # A fault's kind is its class (its YAML tag), not a field: without it, two kinds with
        # the same fields (`!NoPath {task: 1, duration: 9}`, `!OperatorSilent {...}`) would match.
        return {"kind": value.kind.value, **fields} if isinstance(value, FaultConfig) else fields
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, enum.Enum):
        return _plain(value.value)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _flat(tree: dict, prefix: str = "") -> dict:
    """The leaves of nested dicts by dotted key, in the dicts' order (lists stay values)."""
    out = {}
    for key, value in tree.items():
        dotted = f"{prefix}{key}"
        if dotted in NOT_COMPARED:
            continue
        if isinstance(value, dict) and value:
            out.update(_flat(value, f"{dotted}."))
        else:
            out[dotted] = value
    return out


def _digest(data) -> str:
    text = json.dumps(data, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def spec_digest(path: str | Path) -> str:
    """A digest of the assembly spec at `path`: of its parsed YAML, so that comments and
    layout do not count and everything else (the `cell:` section included) does."""
    return _digest(_plain(yaml.safe_load(Path(path).read_text(encoding="utf-8"))))


_MISSING = object()


def _show(value) -> str:
    if value is _MISSING:
        return "(none)"
    text = value if isinstance(value, str) else json.dumps(value, separators=(", ", ": "))
    return text if len(text) <= 40 else text[:39] + "…"


@dataclass(frozen=True)
class ScenarioIdentity:
    """What a process runs (see the module docstring): `name`, the `options` that changed it,
    the `assembly` as given and its spec's digest `spec`, the compared settings `values` (dotted
    keys) and their digest `scenario`."""

    name: str
    options: str = ""
    assembly: str = ""
    spec: str = ""
    scenario: str = ""
    values: dict = field(default_factory=dict, compare=False)

    @classmethod
    def of(cls, scenario: Scenario, options: str | Sequence[str] = "") -> ScenarioIdentity:
        """The identity of `scenario` (as loaded, with every option applied); `options` is
        what to show for the options that changed it (a string or the arguments)."""
        if not isinstance(options, str):
            options = shlex.join(options)
        tree = _plain(scenario)
        # The name and the spec are compared on their own; the assembly's path may differ
        # between two working directories while the spec is the same.
        for key in ("name", "assembly"):
            tree.pop(key)
        # A JSON round trip makes these values what the other side decodes (lists, not tuples).
        values = json.loads(json.dumps(_flat(tree)))
        return cls(
            name=scenario.name,
            options=options,
            assembly=scenario.assembly,
            spec=spec_digest(scenario.assembly_path),
            scenario=_digest(values),
            values=values,
        )

    def to_json(self) -> str:
        """The identity as the JSON text of a session message."""
        return json.dumps(dataclasses.asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ScenarioIdentity | None:
        """The identity in a session message's text; None for `{}` (a side that serves no
        scenario: a real cell, a test's stand-in). ValueError if it is not one."""
        data = json.loads(text or "{}")
        if isinstance(data, dict):
            data.pop("link", None)  # the link's mode beside it (`hrc_drake.cell.link.lockstep`)
        if data == {}:
            return None
        if not isinstance(data, dict) or not isinstance(data.get("values"), dict):
            raise ValueError(f"not a scenario identity: {text[:60]!r}")
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in data.items() if k in names})

    @property
    def label(self) -> str:
        """The name and the options, as the user gave them."""
        return " ".join(filter(None, (self.name or "(unnamed)", self.options)))

    def matches(self, other: ScenarioIdentity) -> bool:
        """Whether `other` runs the same scenario (name, spec and settings)."""
        return (self.name, self.spec, self.scenario) == (other.name, other.spec, other.scenario)

    def differences(self, other: ScenarioIdentity) -> list[tuple[str, str, str]]:
        """(key, this side's value, the other's) of every compared setting that differs, in
        the scenario's order; the spec first."""
        found = []
        if self.spec != other.spec:
            found.append(
                (
                    "assembly",
                    f"{self.assembly} {self.spec[:8]}",
                    f"{other.assembly} {other.spec[:8]}",
                )
            )
        keys = [*self.values, *(k for k in other.values if k not in self.values)]
        for key in keys:
            mine, theirs = self.values.get(key, _MISSING), other.values.get(key, _MISSING)
            if mine != theirs:
                found.append((key, _show(mine), _show(theirs)))
        return found


def _listed(pairs: list[tuple[str, str]], more: int) -> str:
    if not pairs:
        return ""
    text = ", ".join(f"{key} {value}" for key, value in pairs)
    return f" ({text}{f' and {more} more' if more else ''})"


def mismatch(mine: ScenarioIdentity, theirs: ScenarioIdentity | None, side: str) -> str | None:
    """None when the two sides run the same scenario (or the other states none); else one line
    naming what differs, as `side` ("station" or "controller") says it."""
    if theirs is None or mine.matches(theirs):
        return None
    differ = mine.differences(theirs)
    more = max(0, len(differ) - SHOWN)
    ours = _listed([(k, m) for k, m, _ in differ[:SHOWN]], more)
    other = _listed([(k, t) for k, _, t in differ[:SHOWN]], more)
    if side == "station":
        said = (
            f"the controller runs scenario {theirs.label}{other}, "
            f"this station serves {mine.label}{ours}"
        )
    else:
        said = (
            f"the station serves scenario {theirs.label}{other}, "
            f"this controller runs {mine.label}{ours}"
        )
    return f"{said}: start both with the same scenario options"


__all__ = ["NOT_COMPARED", "ScenarioIdentity", "mismatch", "spec_digest"]
