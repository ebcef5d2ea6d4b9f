"""Declarative assembly specs: read and validate a YAML file into an `AssemblySpec`.

An assembly spec is a YAML file (see `models/assemblies/flange.yaml`) with these keys:

- ``name``: the assembly's name.
- ``base``: ``symbol`` and number of ``slots`` of the fixture everything is built on.
- ``parts``: symbol -> ``name``, ``count``, ``footprint`` (base slots it covers, adjacent) and,
  for a part others sit on, ``host: {tag}`` (the tag written in tokens of parts on it). A host
  offers one seat over each base slot it covers. Optional ``bolt_time``: seconds the operator
  takes to bolt one such part (default `DEFAULT_BOLT_TIME`; used by time-aware cost tables);
  ``bolts``: how many bolts (each with a nut) the operator fetches for it (default
  `DEFAULT_BOLTS`; the operator's activity on a shared desk).
- ``mounts``: list of ``{part, to, count}``: how many of a part go on the base or on a host part.
  The counts of a part add up to its ``count``.
- ``precedence`` (optional): ``complete_first: [H, ...]`` — once a host H is placed, the parts
  that go on it come next; ``before: [[A, B], ...]`` — every A is placed before any B.
- ``goal``: which complete configurations are correct; ``min_gap: [{parts: [A, B], slots: g}]``
  (any A and B at least g slots apart) and/or ``correct: [[token, ...], ...]`` (an explicit
  list of configurations, e.g. ``correct: [[F3, S12, F01], [F1, S23, F03]]``). Given both, they
  combine with AND: a complete configuration is correct only if it keeps every ``min_gap`` rule
  *and* is in ``correct`` (so a ``correct`` entry that breaks a rule is refused: it could never
  be correct). Complete configurations that fail the goal are *wrong* (a mistake that breaks no
  constraint). Every ``correct`` entry must be buildable: known tokens, one per part, no two on
  one slot or seat, each part on a host together with its host.
- ``mistakes`` (optional): ``[{part, to}]`` placements the operator may confuse with another
  free seat of the same kind.
- ``state_names`` (optional): labels for states, keyed by their space-separated task sequence.
- ``cell`` (optional): the physical cell's layout (plate and tray poses, slot pitch, part model
  files; see `hrc_drake/layout.py`). The task layer keeps it as is; it is not in `spec_hash`.

Each section has its own reader, called in the order above (then every ``correct`` entry is
checked against the whole spec), so the first problem in that order is the one reported. The
values themselves (with the defaults `DEFAULT_BOLT_TIME` and `DEFAULT_BOLTS`) and the placement
tokens they allow are `hrc_drake.tasks.assembly`.

Nothing here is specific to the flange case: another base or product is another file.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from hrc_drake.paths import not_a_file
from hrc_drake.resources import default_assembly
from hrc_drake.tasks.assembly import (
    BASE,
    DEFAULT_BOLTS,
    AssemblySpec,
    GapRule,
    Goal,
    Mount,
    PartType,
    SpecError,
)
from hrc_drake.tasks.tokens import Placement
from hrc_drake.typed_yaml import safe_load_unique, yaml_error_line

_SYMBOL = re.compile(r"^[A-Z][A-Za-z]*$")


def _fail(source: str, key: str, problem: str) -> SpecError:
    return SpecError(f"assembly spec {source}: {key}: {problem}")


def _require(mapping: Mapping[str, Any], key: str, source: str, where: str) -> Any:
    if key not in mapping:
        raise _fail(source, f"{where}{key}", "missing; add it (see models/assemblies/flange.yaml)")
    return mapping[key]


def _positive_int(value: Any, source: str, key: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise _fail(source, key, f"must be a whole number >= {minimum}, got {value!r}")
    return value


def _check_keys(mapping: Any, allowed: set[str], source: str, where: str) -> None:
    if not isinstance(mapping, Mapping):
        raise _fail(source, where or "<top>", f"must be a mapping, got {type(mapping).__name__}")
    unknown = sorted(set(mapping) - allowed)
    if unknown:
        raise _fail(
            source,
            f"{where}{unknown[0]}",
            f"unknown key; allowed keys are {sorted(allowed)}",
        )


def parse_spec(data: Any, source: str = "<memory>") -> AssemblySpec:
    """Validate a spec given as parsed YAML; SpecError naming the key and problem if invalid."""
    _check_keys(
        data,
        {
            "name",
            "base",
            "parts",
            "mounts",
            "precedence",
            "goal",
            "mistakes",
            "state_names",
            "cell",
        },
        source,
        "",
    )
    name = _require(data, "name", source, "")
    if not isinstance(name, str) or not name:
        raise _fail(source, "name", "must be a non-empty string")
    base_symbol, slots = _parse_base(data, source)
    parts = _parse_parts(data, source, base_symbol, slots)
    by_symbol = {p.symbol: p for p in parts}
    mounts = _parse_mounts(data, source, by_symbol)
    _check_mount_counts(parts, mounts, source)
    complete_first, before = _parse_precedence(data, source, by_symbol, mounts)
    rules, correct = _parse_goal(data, source, by_symbol, slots)
    mistakes = _parse_mistakes(data, source, mounts)
    names = data.get("state_names") or {}
    if not isinstance(names, Mapping):
        raise _fail(source, "state_names", "must map 'T1 T2 ...' sequences to labels")
    spec = AssemblySpec(
        name=name,
        base_symbol=base_symbol,
        slots=slots,
        parts=tuple(parts),
        mounts=tuple(mounts),
        complete_first=tuple(complete_first),
        before=tuple(before),
        goal=Goal(tuple(rules), correct),
        mistakes=tuple(mistakes),
        state_names={" ".join(str(k or "").split()): str(v) for k, v in names.items()},
        source=source,
        cell=_cell_section(data.get("cell"), source),
    )
    for i, config in enumerate(correct or ()):
        _check_correct_entry(spec, config, f"goal.correct[{i}]")
    return spec


def _parse_base(data: Mapping[str, Any], source: str) -> tuple[str, int]:
    """`base`: the fixture's symbol (default ``B``) and its number of slots."""
    base = _require(data, "base", source, "")
    _check_keys(base, {"symbol", "slots"}, source, "base.")
    base_symbol = str(base.get("symbol", "B"))
    slots = _positive_int(_require(base, "slots", source, "base."), source, "base.slots")
    return base_symbol, slots


def _parse_parts(
    data: Mapping[str, Any], source: str, base_symbol: str, slots: int
) -> list[PartType]:
    """`parts`: one part type per symbol, in the file's order."""
    raw_parts = _require(data, "parts", source, "")
    if not isinstance(raw_parts, Mapping) or not raw_parts:
        raise _fail(source, "parts", "must be a non-empty mapping of part symbol -> description")
    return [
        _parse_part(symbol, desc, source, base_symbol, slots) for symbol, desc in raw_parts.items()
    ]


def _parse_part(symbol: Any, desc: Any, source: str, base_symbol: str, slots: int) -> PartType:
    """One entry of `parts`: its symbol, count, footprint (within the base), host tag and
    bolting."""
    key = f"parts.{symbol}"
    if not isinstance(symbol, str) or not _SYMBOL.match(symbol) or symbol == base_symbol:
        raise _fail(source, key, "a part symbol is a capital letter and letters, not the base's")
    _check_keys(
        desc, {"name", "count", "footprint", "host", "bolt_time", "bolts"}, source, key + "."
    )
    count = _positive_int(_require(desc, "count", source, key + "."), source, key + ".count")
    footprint = _positive_int(desc.get("footprint", 1), source, key + ".footprint")
    if footprint > slots:
        raise _fail(
            source,
            key + ".footprint",
            f"slot out of range: covers {footprint} slots but the base has {slots}",
        )
    host_tag = None
    if "host" in desc:
        _check_keys(desc["host"], {"tag"}, source, key + ".host.")
        host_tag = str(desc["host"].get("tag", symbol))
        if not host_tag or not re.fullmatch(r"[0-9A-Za-z]+", host_tag):
            raise _fail(source, key + ".host.tag", "must be letters or digits")
    bolt_time = _bolt_time(desc, source, key)
    bolts = _positive_int(desc.get("bolts", DEFAULT_BOLTS), source, key + ".bolts")
    name = str(desc.get("name", symbol))
    return PartType(symbol, name, count, footprint, host_tag, bolt_time, bolts)


def _bolt_time(desc: Mapping[str, Any], source: str, key: str) -> float | None:
    """A part's `bolt_time` in seconds (None when not given: the default applies)."""
    if "bolt_time" not in desc:
        return None
    bolt_time = desc["bolt_time"]
    number = isinstance(bolt_time, int | float) and not isinstance(bolt_time, bool)
    if not number or not 0 < bolt_time < float("inf"):
        raise _fail(
            source,
            key + ".bolt_time",
            f"must be a positive number of seconds, got {bolt_time!r}",
        )
    return float(bolt_time)


def _parse_mounts(
    data: Mapping[str, Any], source: str, by_symbol: Mapping[str, PartType]
) -> list[Mount]:
    """`mounts`: where the parts go, each (part, place) pair once."""
    raw_mounts = _require(data, "mounts", source, "")
    if not isinstance(raw_mounts, list) or not raw_mounts:
        raise _fail(source, "mounts", "must be a non-empty list of {part, to, count}")
    mounts: list[Mount] = []
    for i, m in enumerate(raw_mounts):
        mounts.append(_parse_mount(m, f"mounts[{i}]", source, by_symbol, mounts))
    return mounts


def _parse_mount(
    m: Any, key: str, source: str, by_symbol: Mapping[str, PartType], earlier: list[Mount]
) -> Mount:
    """One entry of `mounts`: a known part on the base or on a host (not itself, footprint 1),
    not already listed in `earlier`."""
    _check_keys(m, {"part", "to", "count"}, source, key + ".")
    part = _require(m, "part", source, key + ".")
    on = str(m.get("to", BASE))
    if part not in by_symbol:
        raise _fail(source, key + ".part", f"unknown part {part!r}; parts are {list(by_symbol)}")
    if on != BASE:
        if on not in by_symbol:
            raise _fail(source, key + ".to", f"unknown part {on!r}; use 'base' or a part")
        if not by_symbol[on].is_host:
            raise _fail(source, key + ".to", f"part {on!r} has no `host` entry to mount on")
        if on == part:
            raise _fail(source, key + ".to", f"part {part!r} cannot be mounted on itself")
        if by_symbol[part].footprint != 1:
            raise _fail(source, key + ".part", "a part on a host must have footprint 1")
    if any(x.part == part and x.on == on for x in earlier):
        raise _fail(source, key, f"{part} on {on} is listed twice; merge the counts")
    return Mount(part, on, _positive_int(m.get("count"), source, key + ".count"))


def _check_mount_counts(parts: list[PartType], mounts: list[Mount], source: str) -> None:
    """The mounts place every part's count, and no host carries more parts than its seats."""
    for p in parts:
        placed = sum(m.count for m in mounts if m.part == p.symbol)
        if placed != p.count:
            raise _fail(
                source,
                f"parts.{p.symbol}.count",
                f"is {p.count} but the mounts place {placed}; make them agree",
            )
    for p in parts:
        if p.is_host:
            hosted = sum(m.count for m in mounts if m.on == p.symbol)
            if hosted > p.count * p.footprint:
                raise _fail(
                    source,
                    f"mounts (on {p.symbol})",
                    f"{hosted} parts go on {p.symbol} but it offers {p.count * p.footprint} seats",
                )


def _parse_precedence(
    data: Mapping[str, Any], source: str, by_symbol: Mapping[str, PartType], mounts: list[Mount]
) -> tuple[list[str], list[tuple[str, str]]]:
    """`precedence`: the hosts to complete first and the `before` pairs, none contradicting
    the mounts or each other."""
    precedence = data.get("precedence") or {}
    _check_keys(precedence, {"complete_first", "before"}, source, "precedence.")
    complete_first = []
    for i, h in enumerate(precedence.get("complete_first") or []):
        key = f"precedence.complete_first[{i}]"
        if h not in by_symbol:
            raise _fail(source, key, f"unknown part {h!r}")
        hosted = sum(m.count for m in mounts if m.on == h)
        if hosted == 0:
            raise _fail(source, key, f"contradictory precedence: nothing is mounted on {h!r}")
        if hosted % by_symbol[h].count:
            raise _fail(
                source, key, f"{hosted} parts on {by_symbol[h].count} {h!r} do not split evenly"
            )
        complete_first.append(h)
    before = _parse_before(precedence.get("before") or [], source, by_symbol, mounts)
    _check_precedence_cycles(before, source)
    return complete_first, before


def _parse_before(
    pairs: list[Any], source: str, by_symbol: Mapping[str, PartType], mounts: list[Mount]
) -> list[tuple[str, str]]:
    """`precedence.before`: pairs [A, B] of known parts, A not B and A not only on a B."""
    hosts_below: dict[str, set[str]] = {symbol: set() for symbol in by_symbol}
    for m in mounts:
        if m.on != BASE:
            hosts_below[m.part].add(m.on)
    before = []
    for i, pair in enumerate(pairs):
        key = f"precedence.before[{i}]"
        if not isinstance(pair, list) or len(pair) != 2:
            raise _fail(source, key, "must be a pair [A, B]: every A before any B")
        a, b = pair
        for x in (a, b):
            if x not in by_symbol:
                raise _fail(source, key, f"unknown part {x!r}")
        if a == b:
            raise _fail(source, key, f"contradictory precedence: {a!r} before itself")
        if b in hosts_below[a] and not any(m.part == a and m.on == BASE for m in mounts):
            raise _fail(source, key, f"contradictory precedence: {a!r} sits on {b!r}")
        before.append((a, b))
    return before


def _parse_goal(
    data: Mapping[str, Any], source: str, by_symbol: Mapping[str, PartType], slots: int
) -> tuple[list[GapRule], tuple[frozenset[str], ...] | None]:
    """`goal`: its `min_gap` rules and `correct` configurations (their form only: each entry is
    checked against the whole spec once it is built); at least one of the two."""
    goal_data = _require(data, "goal", source, "")
    _check_keys(goal_data, {"min_gap", "correct"}, source, "goal.")
    rules = []
    for i, r in enumerate(goal_data.get("min_gap") or []):
        key = f"goal.min_gap[{i}]"
        _check_keys(r, {"parts", "slots"}, source, key + ".")
        pair = _require(r, "parts", source, key + ".")
        if not isinstance(pair, list) or len(pair) != 2 or any(x not in by_symbol for x in pair):
            raise _fail(source, key + ".parts", f"must name two known parts, got {pair!r}")
        gap = _positive_int(_require(r, "slots", source, key + "."), source, key + ".slots")
        if gap > slots:
            raise _fail(source, key + ".slots", f"slot out of range: gap {gap} > {slots} slots")
        rules.append(GapRule((pair[0], pair[1]), gap))
    correct = None
    if goal_data.get("correct") is not None:
        correct = _correct_shape(goal_data["correct"], source)
    if not rules and not correct:
        raise _fail(source, "goal", "no goal: give `min_gap` rules and/or `correct` configurations")
    return rules, correct


def _parse_mistakes(
    data: Mapping[str, Any], source: str, mounts: list[Mount]
) -> list[tuple[str, str]]:
    """`mistakes`: (part, place) pairs, each one a mount places."""
    mistakes = []
    for i, m in enumerate(data.get("mistakes") or []):
        key = f"mistakes[{i}]"
        _check_keys(m, {"part", "to"}, source, key + ".")
        pair = (m.get("part"), str(m.get("to", BASE)))
        if not any(x.part == pair[0] and x.on == pair[1] for x in mounts):
            raise _fail(source, key, f"no mount places {pair[0]!r} on {pair[1]!r}")
        mistakes.append(pair)
    return mistakes


_CORRECT_FORM = (
    "expected a list of configurations, each a list of task tokens, e.g. "
    "`correct: [[F3, S12, F01], [F1, S23, F03]]`"
)


def _correct_shape(raw: Any, source: str) -> tuple[frozenset[str], ...]:
    """`goal.correct` as configurations; SpecError showing the expected form if it is not."""
    if not isinstance(raw, list) or not raw or all(isinstance(t, str) for t in raw):
        got = "an empty list" if raw == [] else f"{raw!r}"
        if isinstance(raw, list) and raw:
            got += " (a flat list: put each configuration in its own [...])"
        raise _fail(source, "goal.correct", f"{_CORRECT_FORM}; got {got}")
    out = []
    for i, entry in enumerate(raw):
        key = f"goal.correct[{i}]"
        if not isinstance(entry, list) or not all(isinstance(t, str) for t in entry):
            raise _fail(source, key, f"{_CORRECT_FORM}; got {entry!r}")
        repeated = sorted({t for t in entry if entry.count(t) > 1})
        if repeated:
            raise _fail(source, key, f"{entry} lists {repeated[0]!r} twice; one token per part")
        out.append(frozenset(entry))
    return tuple(out)


def _check_correct_entry(spec: AssemblySpec, config: frozenset[str], key: str) -> None:
    """SpecError naming `key` if the configuration cannot be built or breaks a min_gap rule."""
    listed = sorted(config)
    _check_entry_tokens(spec, listed, key)
    where = {t: spec.placement(t) for t in listed}
    _check_entry_seats(spec, listed, where, key)
    _check_entry_gaps(spec, listed, where, key)


def _check_entry_tokens(spec: AssemblySpec, listed: list[str], key: str) -> None:
    """The entry's tokens are known tasks, one per part, as many on each mount as it takes."""
    mounts = {token: mount for token, mount, _ in spec.placements()}
    for token in listed:
        if token not in mounts:
            raise _fail(
                spec.source,
                key,
                f"{listed}: unknown task {token!r} (slot out of range or part unknown); "
                f"tasks are {sorted(mounts)}",
            )
    if len(listed) != spec.total_parts:
        raise _fail(
            spec.source,
            key,
            f"{listed} has {len(listed)} parts but a complete assembly has {spec.total_parts}",
        )
    for mount in spec.mounts:
        placed = [t for t in listed if mounts[t] == mount]
        if len(placed) != mount.count:
            raise _fail(
                spec.source,
                key,
                f"{listed} puts {len(placed)} {mount.part!r} on {mount.on} but the mounts put "
                f"{mount.count} there; it can never be built",
            )


def _check_entry_seats(
    spec: AssemblySpec, listed: list[str], where: Mapping[str, Placement], key: str
) -> None:
    """No two of the entry's parts share a base slot, and each part on a host has that host
    under it."""
    on_base = [t for t in listed if where[t].host is None]
    for a in on_base:
        for b in on_base:
            shared = sorted(set(where[a].slots) & set(where[b].slots))
            if a < b and shared:
                raise _fail(
                    spec.source,
                    key,
                    f"{listed}: {a} and {b} both occupy base slot {shared[0]}; it can never "
                    "be built",
                )
    for t in listed:
        host = where[t].host
        if host is not None and not any(
            where[h].part == host and where[t].slots[0] in where[h].slots for h in on_base
        ):
            raise _fail(
                spec.source,
                key,
                f"{listed}: {t} sits on {host!r} over slot {where[t].slots[0]} but no {host!r} "
                "covers that slot; it can never be built",
            )


def _check_entry_gaps(
    spec: AssemblySpec, listed: list[str], where: Mapping[str, Placement], key: str
) -> None:
    """The entry keeps every `min_gap` rule (the two goals combine with AND)."""
    for r, rule in enumerate(spec.goal.min_gap):
        for a in listed:
            for b in listed:
                if a == b or (where[a].part, where[b].part) != rule.parts:
                    continue
                gap = min(abs(x - y) for x in where[a].slots for y in where[b].slots)
                if gap < rule.slots:
                    raise _fail(
                        spec.source,
                        key,
                        f"{listed} breaks goal.min_gap[{r}] ({a} and {b} are {gap} slot(s) "
                        f"apart, the rule asks at least {rule.slots}): `min_gap` and `correct` "
                        "combine with AND, so this entry can never be correct; drop the entry "
                        "or the rule",
                    )


def _cell_section(cell: Any, source: str) -> Mapping[str, Any] | None:
    if cell is not None and not isinstance(cell, Mapping):
        raise _fail(source, "cell", "must be a mapping of layout values (see hrc_drake/layout.py)")
    return cell


def _check_precedence_cycles(before: list[tuple[str, str]], source: str) -> None:
    graph: dict[str, list[str]] = {}
    for a, b in before:
        graph.setdefault(a, []).append(b)

    def visit(node: str, path: list[str]) -> None:
        if node in path:
            cycle = " before ".join([*path[path.index(node) :], node])
            raise _fail(source, "precedence.before", f"contradictory precedence: {cycle}")
        for nxt in graph.get(node, []):
            visit(nxt, [*path, node])

    for start in graph:
        visit(start, [])


def load_spec(path: str | Path | None = None) -> AssemblySpec:
    """Load and validate an assembly spec file (default: the flange case)."""
    path = Path(path) if path is not None else default_assembly()
    fix = "pass --assembly PATH to an assembly spec .yaml (models/assemblies/flange.yaml)"
    if not path.exists():
        raise SpecError(f"assembly spec {path}: file not found; {fix}")
    if not path.is_file():
        raise SpecError(f"assembly spec {path}: {not_a_file(path)}; {fix}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise SpecError(f"assembly spec {path}: not a text file (not UTF-8); {fix}") from None
    except OSError as err:
        raise SpecError(f"assembly spec {path}: cannot be read ({err.strerror}); {fix}") from None
    try:
        data = safe_load_unique(text)
    except yaml.YAMLError as err:
        raise SpecError(f"assembly spec {yaml_error_line(err, str(path))}") from None
    if data is None:
        raise SpecError(f"assembly spec {path}: the file is empty; {fix}")
    if not isinstance(data, dict):
        raise SpecError(
            f"assembly spec {path}: not a YAML mapping (the file is a {type(data).__name__}, "
            f"not keys such as name:, base:, parts:); {fix}"
        )
    return parse_spec(data, source=str(path))
