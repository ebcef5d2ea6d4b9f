"""Cost tables: the time of every task edge, (state, task) -> seconds, for time-aware decisions,
and the re-target and swap times of a robot that moves on its prediction.

A task's time is the robot's planned motion (pick, carry, place, release, retreat, home to home)
plus the operator's part: the part's bolting time for a placement (``bolt_time`` in the spec,
`DEFAULT_BOLT_TIME` if unset), and an unbolting time, taken equal to the bolting time, for an
undo (the operator removes the bolts, then the robot returns the part to the tray). The table is
keyed by the state (its task sequence) because the robot's path depends on what is in place and
which part is moved: ``undo`` from ``(F1, S23)`` returns the square, from ``(S23, F02)`` a flange.

A placement's entry also gives its carry milestones: ``carry_start``, seconds from the task's
start until the part is lifted out of the tray, and ``carry_end``, until it reaches the pre-place
pose above its seat. A *bet* is a placement the robot committed to before the operator's
indication (`hrc_drake.tasks.interaction`) and the task indicated instead; its ``seconds`` are
what it adds to the indicated task's time at most (planned by the motion layer):

- the same part to another seat, a *re-target*: carry to the committed seat's pre-place pose,
  then on to the indicated seat's, against carrying there directly;
- another part, or undo, a *swap*: pick the committed part, put it back in its tray home and
  release it, then go to the indicated task's pre-grasp, against going there from home.

A table covers the edges and bets a run can take, and leaves out the rest: `run_edges`, every
task out of a state that is not terminal (a run ends at its terminal state, where the MDP has no
action: undo from a terminal state is in the state graph, `task_edges`, never in a run), and
`bet_pairs`, every bet in those states but those on a placement the robot cannot plan (it never
starts on one). An edge the robot cannot plan (no IK, a collision, the solver fails) is the
operator's: the Supervisor hands it over at run time (a ``HANDOVER`` prompt) and the operator
does it by hand, `handover` seconds (the scenario's ``run.handover_time``, as the simulated
operator takes) plus the bolting; the table prices it so, says ``by: operator`` and why, and
never refuses the spec. A bet whose indicated task is the operator's is priced as a swap: the
robot puts its part back, then hands the task over.

A cost table file is JSON (written atomically)::

    {"format": "hrc_drake.costs", "version": 3,
     "spec_name": "flange", "spec_hash": "...", "cell_hash": "...",
     "entries": [{"state": ["F1"], "task": "S23", "seconds": 12.04, "robot": 7.04,
                  "operator": 5.0, "carry_start": 2.69, "carry_end": 4.4},
                 {"state": ["S23", "F03", "F4"], "task": "undo", "seconds": 10.0,
                  "by": "operator", "handover": 5.0, "operator": 5.0,
                  "reason": "task undo: the pre-place pose is unreachable ..."}, ...],
     "bets": [{"state": [], "committed": "F1", "indicated": "F3", "seconds": 0.9}, ...],
     "checksum": sha256 of the canonical JSON of everything above}

``robot``, ``operator`` and the milestones are optional (``robot`` and ``operator`` add up to
``seconds``; for an operator's edge, ``handover`` and ``operator``); ``bets`` is optional as a
whole, and when given covers every bet of `bet_pairs`: a table without them serves the
``wait`` interaction only. Version 2 files (no operator's edges; they may hold undo from
terminal states, which is ignored) are read as they are; version 1 files (no milestones, no
bets) are refused with the fix: plan a new table. The spec hash ties a table to
the assembly it was made for, the cell hash to the robot, cell frames and motion options it was
planned with (see `hrc_drake.cell.run.costs.cell_hash`). This module imports no Drake: tables are
computed by `hrc_drake.cell.run.costs` and used here by the MDP, the solver and `evaluate`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hrc_drake.atomic import atomic_write_text
from hrc_drake.paths import OutputKind, fresh_name
from hrc_drake.tasks.assembly import DEFAULT_BOLT_TIME, AssemblySpec
from hrc_drake.tasks.bets import Bet, bet_kind
from hrc_drake.tasks.datafile import (
    check_made_for,
    first_infeasible,
    has_format,
    load_checked_json,
    with_checksum,
)
from hrc_drake.tasks.graph import StateKind, StateSpace
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.tokens import UNDO

FORMAT = "hrc_drake.costs"
VERSION = 3
READABLE = (2, 3)  # version 2: the same entries, no operator's edges
ROBOT, OPERATOR = "robot", "operator"  # who does an edge (`EdgeCost.by`)

Edge = tuple[tuple[str, ...], str]  # (state as its task sequence, task token)
BetKey = tuple[tuple[str, ...], str, str]  # (state, committed placement, indicated task)


class CostTableError(ValueError):
    """A cost table that cannot be used: corrupted, of another version, spec or cell."""


@dataclass(frozen=True)
class EdgeCost:
    """Time of one task edge [s], its parts when known (robot motion, operator's work), and for a
    placement its carry milestones when known: seconds from the task's start until the part is
    lifted out of the tray (`carry_start`) and until it is above its seat (`carry_end`).

    `by` is who does the task: the robot (`ROBOT`), or the operator by hand (`OPERATOR`) when
    the robot cannot plan it (`reason` says why); then `seconds` is `handover` (fetching the part
    and putting it in place, or taking it out) plus `operator` (the bolting), with no robot time
    and no milestones (`operator_edge`)."""

    seconds: float
    robot: float | None = None
    operator: float | None = None
    carry_start: float | None = None
    carry_end: float | None = None
    by: str = ROBOT
    handover: float | None = None
    reason: str = ""

    @property
    def by_operator(self) -> bool:
        """Whether the operator does the task by hand (the robot cannot plan it)."""
        return self.by == OPERATOR


def operator_edge(handover: float, bolting: float, reason: str) -> EdgeCost:
    """The cost of an edge the robot cannot plan (`reason`): the operator does it by hand,
    `handover` seconds (the scenario's ``run.handover_time``) plus `bolting` (or unbolting)."""
    handover, bolting = round(float(handover), 4), round(float(bolting), 4)
    return EdgeCost(
        round(handover + bolting, 4),
        operator=bolting,
        by=OPERATOR,
        handover=handover,
        reason=reason,
    )


@dataclass(frozen=True, eq=False)
class CostTable:
    """Seconds per task edge of one assembly, planned in one cell.

    `entries` maps ``(state, task)`` — the state as its task sequence, the task a token or
    ``"undo"`` — to an `EdgeCost`. Pass a table as ``Rewards(edge_costs=table)`` to make the MDP
    time-aware (each task's reward is minus its seconds).
    """

    spec_hash: str
    cell_hash: str
    entries: Mapping[Edge, EdgeCost]
    spec_name: str = ""
    bets: Mapping[BetKey, float] | None = None
    """Seconds a bet adds at most, per (state, committed placement, indicated task); None: the
    table has no re-target or swap times (``wait`` only)."""

    def seconds(self, state: tuple[str, ...] | list[str], task: str) -> float:
        """Seconds of `task` from `state`; KeyError naming the edge if the table has none."""
        return self.cost(state, task).seconds

    def cost(self, state: tuple[str, ...] | list[str], task: str) -> EdgeCost:
        """The `EdgeCost` of `task` from `state`; KeyError naming the edge if missing."""
        key = (tuple(state), task)
        try:
            return self.entries[key]
        except KeyError:
            raise KeyError(
                f"cost table has no entry for task {task!r} from state {list(key[0])}; "
                "make a table for this assembly with `hrc-drake costs --out FILE`"
            ) from None

    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self) -> Iterator[Edge]:
        return iter(self.entries)

    def matches(self, spec: AssemblySpec) -> None:
        """Raise CostTableError unless this table was made for `spec`."""
        fix = f"make a new one with `hrc-drake costs --assembly {spec.source} --out FILE`"
        check_made_for("cost table", self.spec_name, self.spec_hash, spec, fix, CostTableError)

    def missing(self, space: StateSpace) -> list[Edge]:
        """Edges a run of `space` can take (`run_edges`) that the table lacks."""
        return [edge for edge in run_edges(space) if edge not in self.entries]

    def by_operator(self, state: tuple[str, ...] | list[str], task: str) -> bool:
        """Whether the table gives `task` from `state` to the operator (the robot cannot plan
        it); False for an edge it does not hold."""
        cost = self.entries.get((tuple(state), task))
        return cost is not None and cost.by_operator

    def operator_edges(self) -> list[Edge]:
        """The edges the operator does by hand (the robot cannot plan them), in table order."""
        return [edge for edge, cost in self.entries.items() if cost.by_operator]

    def with_handover_time(self, handover: float) -> CostTable:
        """This table with its operator's edges priced at `handover` seconds by hand (plus
        their bolting), as a scenario's ``run.handover_time`` says; itself when none differs."""
        priced = {
            edge: operator_edge(handover, cost.operator or 0.0, cost.reason)
            for edge, cost in self.entries.items()
            if cost.by_operator and cost.handover != round(float(handover), 4)
        }
        if not priced:
            return self
        return replace(self, entries={**self.entries, **priced})

    def bet_kind(
        self, space: StateSpace, state: tuple[str, ...] | list[str], committed: str, indicated: str
    ) -> Bet:
        """How a bet plays out (`hrc_drake.tasks.bets.bet_kind`), but that one whose indicated
        task is the operator's is a swap: the robot puts its part back, whatever the seat."""
        kind = bet_kind(space, committed, indicated)
        if kind == Bet.RETARGET and self.by_operator(state, indicated):
            return Bet.SWAP
        return kind

    def bet_seconds(
        self, state: tuple[str, ...] | list[str], committed: str, indicated: str
    ) -> float:
        """The planned seconds of committing to `committed` in `state` when `indicated` comes
        (a re-target or a swap); KeyError naming the bet if the table has none."""
        key = (tuple(state), committed, indicated)
        if self.bets is None or key not in self.bets:
            raise KeyError(
                f"cost table has no re-target or swap time for committing to {committed!r} in "
                f"state {list(key[0])} when {indicated!r} is indicated; make a table with "
                "`hrc-drake costs --out FILE`"
            )
        return self.bets[key]

    def anticipation_problem(self) -> str | None:
        """What the table lacks for a robot that moves on its prediction (None: nothing):
        its bets, or a placement's carry milestones."""
        if self.bets is None:
            return "this table has none (made by hand, or before they were planned)"
        for (state, task), cost in self.entries.items():
            if cost.by_operator:
                continue  # done by hand: the robot never starts on it
            if task != UNDO and (cost.carry_start is None or cost.carry_end is None):
                return f"the placement {task!r} from {list(state)} has no carry milestones"
        return None

    def sequence_seconds(self, sequence: tuple[str, ...] | list[str]) -> float:
        """Seconds of doing `sequence` from the empty base, task after task."""
        seq = tuple(sequence)
        return sum(self.seconds(seq[:i], seq[i]) for i in range(len(seq)))


def bet_pairs(space: StateSpace, by_operator: Collection[Edge] = ()) -> list[BetKey]:
    """Every bet a run can take: in each state that is not terminal, each placement the robot
    may commit to and each other feasible task the operator may indicate; but no bet on a
    placement of `by_operator` (edges the robot cannot plan: it never starts on one)."""
    skip = set(by_operator)
    pairs = []
    for s in range(space.n_states):
        if space.kind[s] == StateKind.TERMINAL:
            continue
        tasks = [t for t, _ in space.tasks(s)]
        state = space.sequence(s)
        pairs += [
            (state, c, t)
            for c in tasks
            if c != UNDO and (state, c) not in skip
            for t in tasks
            if t != c
        ]
    return pairs


def task_edges(space: StateSpace) -> list[Edge]:
    """Every (state, task) edge of the state graph, in state order: placements, then undo.

    Includes undo from terminal states (the graph has a reverse for every edge); a run never
    takes those, and a cost table leaves them out (`run_edges`).
    """
    return [(space.sequence(s), task) for s in range(space.n_states) for task, _ in space.tasks(s)]


def run_edges(space: StateSpace) -> list[Edge]:
    """The edges a run can take, in state order: every task out of a state that is not terminal
    (a run ends at its terminal state, where the MDP has no action). What a cost table covers."""
    return [
        (space.sequence(s), task)
        for s in range(space.n_states)
        if space.kind[s] != StateKind.TERMINAL
        for task, _ in space.tasks(s)
    ]


def operator_seconds(spec: AssemblySpec, state: tuple[str, ...], task: str) -> float:
    """The operator's time for a task edge: bolting the part placed, or unbolting the part undone.

    Unbolting is taken to last as long as bolting (our assumption; nothing is published).
    """
    if task == UNDO:
        if not state:
            raise ValueError("undo from the empty base: nothing to unbolt")
        token = state[-1]
    else:
        token = task
    return bolt_time(spec, spec.placement(token).part)


def bolt_time(spec: AssemblySpec, symbol: str) -> float:
    """Seconds the operator takes to bolt one part of type `symbol` (spec or default)."""
    part = spec.part(symbol)
    return DEFAULT_BOLT_TIME if part.bolt_time is None else float(part.bolt_time)


def table_from_seconds(
    space: StateSpace,
    seconds: Mapping[Edge, float],
    cell_hash: str = "by-hand",
    carry: tuple[float, float] | None = None,
    bets: Mapping[BetKey, float] | None = None,
) -> CostTable:
    """A CostTable for `space` from plain seconds per edge (tests, hand-made tables); with
    `carry`, every placement's (carry_start, carry_end), and `bets` their seconds."""
    start, end = carry if carry is not None else (None, None)
    entries = {
        (tuple(s), t): EdgeCost(
            float(v), carry_start=None if t == UNDO else start, carry_end=None if t == UNDO else end
        )
        for (s, t), v in seconds.items()
    }
    return CostTable(
        spec_hash=space.spec.spec_hash,
        cell_hash=cell_hash,
        entries=entries,
        spec_name=space.spec.name,
        bets=None if bets is None else dict(bets),
    )


def uniform_bets(space: StateSpace, retarget: float, swap: float) -> dict[BetKey, float]:
    """Every bet of `space` at one re-target and one swap figure (hand-made tables)."""
    return {
        (s, c, t): retarget if bet_kind(space, c, t) == Bet.RETARGET else swap
        for s, c, t in bet_pairs(space)
    }


def _payload(table: CostTable) -> dict[str, Any]:
    entries = []
    for (state, task), cost in sorted(table.entries.items(), key=lambda kv: (len(kv[0][0]), kv[0])):
        entry: dict[str, Any] = {"state": list(state), "task": task, "seconds": cost.seconds}
        if cost.robot is not None:
            entry["robot"] = cost.robot
        if cost.operator is not None:
            entry["operator"] = cost.operator
        if cost.carry_start is not None and cost.carry_end is not None:
            entry["carry_start"], entry["carry_end"] = cost.carry_start, cost.carry_end
        if cost.by_operator:
            entry.update(by=OPERATOR, handover=cost.handover, reason=cost.reason)
        entries.append(entry)
    payload = {
        "format": FORMAT,
        "version": VERSION,
        "spec_name": table.spec_name,
        "spec_hash": table.spec_hash,
        "cell_hash": table.cell_hash,
        "entries": entries,
    }
    if table.bets is not None:
        payload["bets"] = [
            {"state": list(state), "committed": c, "indicated": t, "seconds": seconds}
            for (state, c, t), seconds in sorted(
                table.bets.items(), key=lambda kv: (len(kv[0][0]), kv[0])
            )
        ]
    return payload


def save_cost_table(table: CostTable, path: str | Path) -> None:
    """Save atomically, with the spec and cell hashes and a checksum of the content."""
    atomic_write_text(Path(path), json.dumps(with_checksum(_payload(table)), indent=1) + "\n")


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise TypeError(f"{what} must be a number, got {value!r}")
    if value < 0:
        raise ValueError(f"{what} must be >= 0, got {value!r}")
    return float(value)


def is_cost_table_file(path: str | Path) -> bool:
    """Whether `path` is a cost table file (its `format` says so; of any version): `hrc-drake
    costs` replaces it without `--force`."""
    return has_format(path, FORMAT)


COST_TABLE_FILE = OutputKind("cost table", is_cost_table_file, "costs.json")


def load_cost_table(path: str | Path, space: StateSpace, cell_hash: str | None = None) -> CostTable:
    """Load a cost table made for `space`'s spec (and, if given, that cell hash).

    CostTableError with the fix if the file is missing, corrupted (not JSON, checksum, bad
    entry), of another version or another spec or cell, names a task that is not feasible, or
    lacks an edge a run can take (`run_edges`). Entries for other edges of the state graph (undo
    from a terminal state, in version 2 files) are kept and never used.
    """
    path = Path(path)
    # Never advise writing over a file that is not a cost table: a fresh name instead.
    out = path if not path.exists() or is_cost_table_file(path) else None
    fix = f"make a new one with `hrc-drake costs --out {out or fresh_name(path, 'costs', '.json')}`"
    payload = load_checked_json(
        path,
        what="cost table",
        fmt=FORMAT,
        version=VERSION,
        fix=fix,
        error=CostTableError,
        older={1: "without the re-target and swap times"},
        readable=READABLE,
    )
    try:
        table = CostTable(
            spec_hash=str(payload["spec_hash"]),
            cell_hash=str(payload["cell_hash"]),
            entries=_entries(payload["entries"]),
            spec_name=str(payload.get("spec_name", "")),
            bets=None if payload.get("bets") is None else _bets(payload["bets"]),
        )
    except (KeyError, TypeError, ValueError) as err:
        raise CostTableError(f"cost table {path} is corrupted (bad entry: {err}); {fix}") from None
    try:
        table.matches(space.spec)
    except CostTableError as err:
        raise CostTableError(f"{path}: {err}") from None
    if cell_hash is not None and table.cell_hash != cell_hash:
        raise CostTableError(
            f"cost table {path} was planned for another cell (cell hash {table.cell_hash}, "
            f"this cell {cell_hash}); {fix}"
        )
    problem = first_infeasible(space, table.entries)
    if problem is not None:
        raise CostTableError(f"cost table {path} {problem}; {fix}")
    missing = table.missing(space)
    if missing:
        state, task = missing[0]
        raise CostTableError(
            f"cost table {path} has no entry for task {task!r} from {list(state)} "
            f"({len(missing)} edges missing); {fix}"
        )
    if table.bets is not None:
        _check_bets(path, space, table, fix)
    return table


def _optional(entry: Mapping[str, Any], key: str, i: int) -> float | None:
    return None if entry.get(key) is None else _number(entry[key], f"entry {i} {key}")


def _entries(raw: list) -> dict[Edge, EdgeCost]:
    entries: dict[Edge, EdgeCost] = {}
    for i, e in enumerate(raw):
        key = (tuple(e["state"]), str(e["task"]))
        if key in entries:
            raise ValueError(f"entry {i} repeats task {key[1]!r} from {list(key[0])}")
        cost = EdgeCost(
            _number(e["seconds"], f"entry {i} seconds"),
            *(_optional(e, k, i) for k in ("robot", "operator", "carry_start", "carry_end")),
        )
        if cost.carry_start is not None and not (cost.carry_end or 0.0) >= cost.carry_start:
            raise ValueError(f"entry {i}: carry_end must follow carry_start")
        by = e.get("by", ROBOT)
        if by == OPERATOR:
            if cost.robot is not None or cost.carry_start is not None:
                raise ValueError(f"entry {i}: an operator's edge has no robot time or milestones")
            handover = _number(e.get("handover"), f"entry {i} handover")
            cost = replace(cost, by=OPERATOR, handover=handover, reason=str(e.get("reason", "")))
        elif by != ROBOT:
            raise ValueError(f"entry {i}: by must be {ROBOT!r} or {OPERATOR!r}, got {by!r}")
        entries[key] = cost
    return entries


def _bets(raw: list) -> dict[BetKey, float]:
    bets: dict[BetKey, float] = {}
    for i, b in enumerate(raw):
        key = (tuple(b["state"]), str(b["committed"]), str(b["indicated"]))
        if key in bets:
            raise ValueError(f"bet {i} repeats {key[1]!r} -> {key[2]!r} in {list(key[0])}")
        bets[key] = _number(b["seconds"], f"bet {i} seconds")
    return bets


def _check_bets(path: Path, space: StateSpace, table: CostTable, fix: str) -> None:
    """CostTableError unless the bets are exactly the state graph's, with carry milestones."""
    assert table.bets is not None
    wanted = set(bet_pairs(space, table.operator_edges()))
    for state, committed, indicated in table.bets:
        if (state, committed, indicated) not in wanted:
            raise CostTableError(
                f"cost table {path} has a bet on {committed!r} -> {indicated!r} in "
                f"{list(state)}, which is not a bet of {space.spec.name!r}; {fix}"
            )
    missing = [key for key in wanted if key not in table.bets]
    if missing:
        state, committed, indicated = min(missing)
        raise CostTableError(
            f"cost table {path} has no bet on {committed!r} -> {indicated!r} in {list(state)} "
            f"({len(missing)} bets missing); {fix}"
        )
    problem = table.anticipation_problem()
    if problem:
        raise CostTableError(f"cost table {path}: {problem}; {fix}")


def shortest_sequences(space: StateSpace) -> list[tuple[str, ...]]:
    """Sequences from the empty base to a terminal state in the fewest tasks (no undo).

    For the flange case: the four the paper calls optimal, equivalent under -1 per task.
    """
    terminal = np.flatnonzero(space.kind == StateKind.TERMINAL)
    fewest = int(space.depth[terminal].min())
    return [space.sequence(int(s)) for s in terminal if space.depth[s] == fewest]


def cost_summary(
    space: StateSpace, table: CostTable, config: MdpConfig | None = None
) -> dict[str, Any]:
    """The shortest sequences ranked by seconds, and the choices of the unit-cost and the
    time-aware exact policies, as JSON-ready data.

    Per sequence: ``seconds`` when every task goes as proposed, and ``expected_seconds``
    when the operator misplaces parts as `config` says (default `MdpConfig`, gamma 1): the value of
    starting with the sequence's first task and acting optimally (time-aware, gamma 1) after.
    The time-aware choice minimises the expected seconds; its ``tasks`` are the route when the
    operator follows the robot.
    """
    from hrc_drake.tasks.decide import run_decisions
    from hrc_drake.tasks.policy import policy_from_choices
    from hrc_drake.tasks.solve import exact_policy, solve_exact, timed_config

    mdp = build_mdp(space, timed_config(table, config))
    solution = solve_exact(mdp)
    first_q = {mdp.task_name(e): -float(solution.q[e]) for e in mdp.edges_of(0)}

    def row(seq: tuple[str, ...]) -> dict[str, Any]:
        states = [space.index(seq[:i]) for i in range(len(seq) + 1)]
        return {
            "states": " ".join(space.name(s) for s in states),
            "tasks": list(seq),
            "seconds": round(table.sequence_seconds(seq), 3),
            "task_seconds": [round(table.seconds(seq[:i], seq[i]), 3) for i in range(len(seq))],
            "expected_seconds": round(first_q[seq[0]], 3) if seq else 0.0,
        }

    ranked = sorted(
        (row(seq) for seq in shortest_sequences(space)),
        key=lambda r: (r["seconds"], r["expected_seconds"]),
    )
    unit, _ = run_decisions(space, exact_policy(space))
    timed, _ = run_decisions(space, policy_from_choices(mdp, solution.choice, "exact/time"))
    return {
        "assembly": space.spec.name,
        "spec_hash": table.spec_hash,
        "cell_hash": table.cell_hash,
        "edges": len(table),
        "mistake_prob": mdp.config.mistake_prob,
        "shortest_sequences": ranked,
        "unit_cost_choice": row(unit[-1]),
        "time_aware_choice": row(timed[-1]),
    }
