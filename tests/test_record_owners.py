"""One owner per record (issue 51): each record of the Supervisor's status is written by one
module of `hrc_drake.cell.controller`, and its mode only through the table of transitions.

The check reads the source (ast): a write is `dataclasses.replace(x, field=...)` on a record,
a record's constructor with the field (by keyword or position), or an assignment to
`x.field`. Which record `x` is comes from annotations, assignments, the records' own field
types and functions' return annotations; a `replace` the check cannot place, or one that
forwards `**changes` (a setter any part may call), fails it.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import types
import typing
from pathlib import Path

import pytest

import hrc_drake.cell.controller as controller_package
from hrc_drake.cell.controller.supervisor_state import (
    TRANSITIONS,
    Event,
    Mode,
    SupervisorStatus,
    TransitionError,
    transition,
)

CONTROLLER = Path(controller_package.__file__).parent
# The forecast's own values (an `Anchor` held in `KeepClearState.seen`) are its outputs, as a
# `Plan` is the planner's: not records of the Supervisor.
NOT_RECORDS = ("hrc_drake.cell.controller.forecast",)

# The one module that writes each record (each field of `SupervisorStatus` by its name).
STATUS_OWNERS = {
    "supervisor_state": ("mode", "settle_until", "events"),
    "follower": ("clock", "q_hold", "opening_hold", "retreat"),
    "question": ("question",),
    "planning": ("ask",),
    "anticipation": ("turn",),
    "keep_clear": ("clear",),
    "recovery": ("recovery", "detections", "error", "capped"),
    "supervisor": ("state", "step", "task", "tokens_before", "bolted", "planned_ahead"),
}
STATUS_OWNERS["supervisor"] += ("guard", "history")
RECORD_OWNERS = {
    "PlanClock": "follower",
    "HeldWait": "follower",
    "Question": "question",
    "PlanAsk": "planning",
    "TurnState": "anticipation",
    "KeepClearState": "keep_clear",
    "RecoveryState": "recovery",
    "Detection": "recovery",
    "Retreat": "recovery",
    "GuardState": "guard",
    "TaskInFlight": "supervisor",
    "TaskRecord": "observe",
}


def _unwrap(hint) -> type | None:
    """The one class a field or return hint names (`X | None` is X; a union of two: none)."""
    if isinstance(hint, type) and typing.get_origin(hint) is None:
        return hint
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return _unwrap(args[0]) if len(args) == 1 else None
    return None


def _element(hint) -> type | None:
    """The element class of a `tuple[X, ...]` or `frozenset[X]` hint."""
    args = typing.get_args(hint)
    return _unwrap(args[0]) if typing.get_origin(hint) in (tuple, frozenset) and args else None


def _known_classes() -> dict[str, type]:
    """Every class a controller module names, by name."""
    known: dict[str, type] = {}
    for path in sorted(CONTROLLER.glob("*.py")):
        module = importlib.import_module(f"hrc_drake.cell.controller.{path.stem}")
        for name, value in vars(module).items():
            if isinstance(value, type):
                known.setdefault(name, value)
    return known


def _records() -> dict[type, set[str]]:
    """The status's records: `SupervisorStatus` and the dataclasses its fields hold, down to
    the last, defined in the controller (the forecast's values aside), with their fields."""
    found: dict[type, set[str]] = {}
    todo = [SupervisorStatus]
    while todo:
        cls = todo.pop()
        if cls in found:
            continue
        found[cls] = {f.name for f in dataclasses.fields(cls)}
        for hint in typing.get_type_hints(cls).values():
            for inner in (_unwrap(hint), _element(hint)):
                if (
                    inner is not None
                    and dataclasses.is_dataclass(inner)
                    and inner.__module__.startswith("hrc_drake.cell.controller")
                    and inner.__module__ not in NOT_RECORDS
                ):
                    todo.append(inner)
    return found


KNOWN = _known_classes()
RECORDS = _records()


def _member_hint(cls: type, name: str):
    """The hint of `cls.name`: a field's type, a property's or a method's return."""
    if dataclasses.is_dataclass(cls) and name in {f.name for f in dataclasses.fields(cls)}:
        return typing.get_type_hints(cls).get(name)
    member = inspect.getattr_static(cls, name, None)
    if isinstance(member, property):
        member = member.fget
    if isinstance(member, staticmethod | classmethod):
        member = member.__func__
    if callable(member):
        try:
            return typing.get_type_hints(member).get("return")
        except (NameError, TypeError):
            return None
    return None


class _Module:
    """One module's source, with what the check needs to place a `replace`."""

    def __init__(self, name: str, source: str, returns: dict[str, type | None]):
        self.name, self.tree, self.returns = name, ast.parse(source), returns
        self.aliases = {
            (a.asname or a.name).split(".")[-1]
            for node in ast.walk(self.tree)
            if isinstance(node, ast.ImportFrom | ast.Import)
            for a in node.names
            if a.name[:1].islower()
        }


def _annotation_class(node: ast.AST | None) -> type | None:
    """The class an annotation names (`X`, `X | None`, `"X"`)."""
    if node is None:
        return None
    text = node.value if isinstance(node, ast.Constant) else ast.unparse(node)
    names = [part.strip() for part in str(text).split("|") if part.strip() != "None"]
    return KNOWN.get(names[0]) if len(names) == 1 else None


def _return_table(trees: list[ast.AST]) -> dict[str, type | None]:
    """Each function name's return class across the sources (None: unannotated or two)."""
    table: dict[str, set] = {}
    for tree in trees:
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef):
                table.setdefault(node.name, set()).add(_annotation_class(node.returns))
    return {name: next(iter(found)) if len(found) == 1 else None for name, found in table.items()}


def _type_of(node: ast.AST, env: dict[str, type], module: _Module) -> type | None:
    """The class of the value of `node`, as far as the source tells."""
    if isinstance(node, ast.Name):
        return env.get(node.id)
    if isinstance(node, ast.Attribute):
        base = _type_of(node.value, env, module)
        return _unwrap(_member_hint(base, node.attr)) if base is not None else None
    if isinstance(node, ast.IfExp):
        return _type_of(node.body, env, module) or _type_of(node.orelse, env, module)
    if isinstance(node, ast.BoolOp):
        return next((t for v in node.values if (t := _type_of(v, env, module))), None)
    if not isinstance(node, ast.Call):
        return None
    func = node.func
    if isinstance(func, ast.Name):
        if func.id == "replace" and node.args:
            return _type_of(node.args[0], env, module)
        if func.id in KNOWN and dataclasses.is_dataclass(KNOWN[func.id]):
            return KNOWN[func.id]
        return module.returns.get(func.id)
    if isinstance(func, ast.Attribute):
        if isinstance(func.value, ast.Name) and func.value.id in module.aliases:
            return module.returns.get(func.attr)
        base = _type_of(func.value, env, module)
        if base is not None:
            return _unwrap(_member_hint(base, func.attr))
        return module.returns.get(func.attr)
    return None


def _environment(func: ast.FunctionDef, owner: type | None, module: _Module) -> dict:
    """The classes of `func`'s names: annotated parameters, `self` of a record's method, and
    names assigned (in source order) or iterated over a record's tuple."""
    env: dict[str, type] = {}
    arguments = [*func.args.posonlyargs, *func.args.args, *func.args.kwonlyargs]
    for arg in arguments:
        cls = _annotation_class(arg.annotation)
        if cls is not None:
            env[arg.arg] = cls
    if owner is not None and arguments and arguments[0].arg == "self":
        env["self"] = owner
    nodes = sorted(
        (n for n in ast.walk(func) if isinstance(n, ast.Assign | ast.comprehension | ast.For)),
        key=lambda n: (getattr(n, "lineno", 0), getattr(n, "col_offset", 0)),
    )
    for node in nodes:
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            pairs = [(node.targets[0], node.value)]
            if isinstance(node.value, ast.Tuple) and isinstance(node.targets[0], ast.Tuple):
                pairs = list(zip(node.targets[0].elts, node.value.elts, strict=False))
            for target, value in pairs:
                cls = _type_of(value, env, module)
                if isinstance(target, ast.Name) and cls is not None:
                    env[target.id] = cls
        elif (
            isinstance(node, ast.comprehension | ast.For)
            and isinstance(node.target, ast.Name)
            and isinstance(node.iter, ast.Attribute)
        ):
            base = _type_of(node.iter.value, env, module)
            cls = _element(_member_hint(base, node.iter.attr)) if base else None
            if cls is not None:
                env[node.target.id] = cls
    return env


def _writes(module: _Module) -> tuple[list, list[str]]:
    """(the record writes in `module`: (record, field, line, value), the problems found)."""
    writes, problems = [], []
    fields_anywhere = set().union(*RECORDS.values())
    where = f"{module.name}.py"
    scopes: list[tuple[ast.AST, type | None]] = []
    for node in ast.walk(module.tree):
        if isinstance(node, ast.ClassDef):
            owner = KNOWN.get(node.name)
            scopes += [(f, owner) for f in node.body if isinstance(f, ast.FunctionDef)]
    methods = {id(f) for f, _ in scopes}
    scopes += [
        (f, None)
        for f in ast.walk(module.tree)
        if isinstance(f, ast.FunctionDef) and id(f) not in methods
    ]
    for func, owner in scopes:
        env = _environment(func, owner, module)
        for node in ast.walk(func):
            if isinstance(node, ast.Assign | ast.AugAssign):
                for target in getattr(node, "targets", [getattr(node, "target", None)]):
                    if isinstance(target, ast.Attribute):
                        cls = _type_of(target.value, env, module)
                        if cls in RECORDS:
                            writes.append((cls, target.attr, node.lineno, node.value))
            if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Name):
                continue
            is_replace = node.func.id == "replace" and node.args
            cls = _type_of(node.args[0], env, module) if is_replace else KNOWN.get(node.func.id)
            named = [k.arg for k in node.keywords if k.arg is not None]
            if cls not in RECORDS:
                if is_replace and cls is None and set(named) & fields_anywhere:
                    problems.append(
                        f"{where}:{node.lineno}: cannot tell which record "
                        f"`{ast.unparse(node)[:60]}` writes: annotate the value replaced"
                    )
                continue
            if any(k.arg is None for k in node.keywords):
                problems.append(
                    f"{where}:{node.lineno}: `{ast.unparse(node)[:60]}` forwards **changes to "
                    f"{cls.__name__}: a setter any part may call; write named fields"
                )
            positional = [] if is_replace else [f.name for f in dataclasses.fields(cls)]
            values = [*zip(positional, node.args, strict=False)]
            values += [(k.arg, k.value) for k in node.keywords if k.arg is not None]
            writes += [(cls, name, node.lineno, value) for name, value in values]
    return writes, problems


def analyse(sources: dict[str, str]) -> list[str]:
    """The problems with record ownership in `sources` ({module name: source}): fields
    written by another module than their owner, the mode written other than through
    `transition`, and writes the check cannot place."""
    trees = {name: ast.parse(text) for name, text in sources.items()}
    returns = _return_table(list(trees.values()))
    status_owner = {f: m for m, names in STATUS_OWNERS.items() for f in names}
    problems = []
    for name, text in sorted(sources.items()):
        writes, found = _writes(_Module(name, text, returns))
        problems += found
        for cls, field, line, value in writes:
            if cls is SupervisorStatus:
                owner = status_owner.get(field, "(no owner: add it to STATUS_OWNERS)")
            else:
                owner = RECORD_OWNERS.get(cls.__name__, "(no owner: add it to RECORD_OWNERS)")
            if owner != name:
                problems.append(
                    f"{name}.py:{line}: writes {cls.__name__}.{field}, which only {owner} "
                    "writes: ask the owner's function for the change"
                )
            is_transition = (
                isinstance(value, ast.Call)
                and isinstance(value.func, ast.Name)
                and value.func.id == "transition"
            )
            if cls is SupervisorStatus and field == "mode" and not is_transition:
                problems.append(
                    f"{name}.py:{line}: sets the mode to `{ast.unparse(value)}` past the "
                    "table: use SupervisorStatus.enter(event)"
                )
    return problems


def controller_sources() -> dict[str, str]:
    """The controller's modules, {name: source}."""
    return {p.stem: p.read_text() for p in sorted(CONTROLLER.glob("*.py"))}


def test_each_record_of_the_supervisor_has_one_writing_module():
    """Every field of the status and of its records is written only by its owner."""
    problems = analyse(controller_sources())
    assert not problems, "\n".join(problems)


def test_the_check_finds_a_second_writer_a_generic_setter_and_a_mode_past_the_table():
    """The check itself: the shapes the Supervisor had before each part owned its record."""
    sources = {
        "recovery": (
            "def f(s: SupervisorStatus):\n"
            "    return replace(s, clock=replace(s.clock, plan=None), mode=Mode.FAILED)\n"
        ),
        "supervisor_state": (
            "class SupervisorStatus:\n"
            "    def noted(self, event, **changes):\n"
            "        return replace(self, events=(*self.events, event), **changes)\n"
        ),
        "anticipation": "def g(s):\n    return replace(s, turn=None)\n",
    }
    problems = "\n".join(analyse(sources))
    assert "writes SupervisorStatus.clock, which only follower writes" in problems
    assert "writes PlanClock.plan, which only follower writes" in problems
    assert "sets the mode to `Mode.FAILED` past the table" in problems
    assert "forwards **changes to SupervisorStatus" in problems
    assert "cannot tell which record" in problems


def test_every_status_field_and_record_has_an_owner():
    """The owners' table names every field of the status and every record once."""
    listed = [f for names in STATUS_OWNERS.values() for f in names]
    assert sorted(listed) == sorted(f.name for f in dataclasses.fields(SupervisorStatus))
    assert {c.__name__ for c in RECORDS} - {"SupervisorStatus"} == set(RECORD_OWNERS)


def test_the_mode_changes_only_as_the_table_lists():
    """A transition the table lists goes through; one it does not is refused, in one line."""
    assert transition(Mode.PLAN, Event.PLAN_STARTED) == Mode.EXECUTE
    assert all(transition(mode, Event.STOPPED) == Mode.FAILED for mode in Mode)
    assert (Mode.DONE, Event.PLAN_ASKED) not in TRANSITIONS
    with pytest.raises(TransitionError, match="no transition from mode 'done' on event"):
        transition(Mode.DONE, Event.PLAN_ASKED)
    status = SupervisorStatus(mode=Mode.SETTLE)
    assert status.enter(Event.TASK_READ).mode == Mode.DECIDE
    with pytest.raises(TransitionError, match="'settle' on event 'plan-started'"):
        status.enter(Event.PLAN_STARTED)
