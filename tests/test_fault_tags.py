"""A scenario's `faults:` are tagged variants, as Drake's `model_drivers` are: the strict
Drake-free loader (`hrc_drake.typed_yaml`) and Drake's `yaml_load_typed` read the same tagged
text into the same value, and the strict one refuses an untagged entry, an unknown tag and the
old `{kind: K}` form in one line naming the entry and the tags."""

from dataclasses import dataclass, field

import pytest
from pydrake.common.yaml import yaml_load_typed

from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.hri.faults import (
    FAULT_CLASSES,
    FaultKind,
    GripLost,
    GripperStuck,
    NoPath,
    NoSeat,
    OperatorSilent,
    ProtectiveStop,
    Pushed,
    Stuck,
    TrackerLoss,
)
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import Scenario, ScenarioError
from hrc_drake.typed_yaml import TypedYamlError, dump_flow, load_tagged, load_typed

TAGS = (
    "!GripLost, !NoSeat, !GripperStuck, !NoPath, !OperatorSilent, !ProtectiveStop, !Pushed, "
    "!TrackerLoss, !SafetySensorSilent"
)

FAULT_TEXTS = [
    "{faults: [!GripLost {task: 2}, !Pushed {task: 1, torque: 150}]}",
    "{faults: [!NoSeat {task: 3, obstacle: true}, !NoSeat {task: 1, offset: 0.01, after: 0.5}]}",
    "{faults: [!GripperStuck {task: 1, stuck: open}, !GripperStuck {task: 2}]}",
    "{faults: [!NoPath {task: 2, duration: 9}, !OperatorSilent {task: 1}]}",
    "faults:\n  - !ProtectiveStop {task: 2, after: 1.5}\n  - !Pushed\n    task: 1\n"
    "    joint: elbow_joint\n    duration: 0.5\n",
    "{faults: [!TrackerLoss {task: 2, after: 3.5, duration: 1}]}",
    "{faults: []}",
]


def test_each_kind_has_its_tag_and_its_own_defaults():
    assert {kind: cls.__name__ for kind, cls in FAULT_CLASSES.items()} == {
        FaultKind.GRIP_LOST: "GripLost",
        FaultKind.NO_SEAT: "NoSeat",
        FaultKind.GRIPPER_STUCK: "GripperStuck",
        FaultKind.NO_PATH: "NoPath",
        FaultKind.OPERATOR_SILENT: "OperatorSilent",
        FaultKind.PROTECTIVE_STOP: "ProtectiveStop",
        FaultKind.PUSHED: "Pushed",
        FaultKind.TRACKER_LOSS: "TrackerLoss",
        FaultKind.SAFETY_SENSOR_SILENT: "SafetySensorSilent",
    }
    text = (
        "{faults: [!GripLost {task: 1}, !NoSeat {task: 1}, !GripperStuck {task: 1}, "
        "!NoPath {task: 1}, !OperatorSilent {task: 1}, !ProtectiveStop {task: 1}, "
        "!Pushed {task: 1}, !TrackerLoss {task: 1}]}"
    )
    assert load_scenario("row1-optimal", text).faults == [
        GripLost(task=1, force=1.0, after=1.0),
        NoSeat(task=1, offset=0.008, after=0.8, obstacle=False),
        GripperStuck(task=1, stuck="close"),
        NoPath(task=1, duration=6.0),
        OperatorSilent(task=1, duration=15.0),
        ProtectiveStop(task=1, after=4.0, duration=2.0),
        Pushed(task=1, torque=80.0, joint="shoulder_pan_joint", after=4.0, duration=0.3),
        TrackerLoss(task=1, after=4.0, duration=1.0),
    ]
    assert GripperStuck().stuck == Stuck.CLOSE and {s.value for s in Stuck} == {"close", "open"}


@pytest.mark.parametrize("text", FAULT_TEXTS)
def test_drake_loads_the_same_tagged_faults(text):
    ours = load_typed(Scenario, text=text)
    drakes = yaml_load_typed(schema=Scenario, data=text)
    assert ours.faults == drakes.faults
    assert [type(f) for f in ours.faults] == [type(f) for f in drakes.faults]


@pytest.mark.parametrize(
    ("entry", "words"),
    [
        ("{kind: grip-lost, task: 1}", ["the kind is a tag, not a key", "!GripLost {task: 1}"]),
        (
            "{kind: pushed, task: 1, torque: 150}",
            ["the kind is a tag, not a key", "!Pushed {task: 1, torque: 150}"],
        ),
        ("{kind: slip, task: 1}", ["'slip' is none", "!GripLost {task: 1}"]),
        ("{task: 1}", ["untagged {task: 1}", "e.g. !GripLost {task: 1}"]),
        ("!Slip {task: 1}", ["unknown tag !Slip"]),
        ("!GripLst {task: 1}", ["unknown tag !GripLst (did you mean !GripLost?)"]),
        ("3", ["expected a tagged mapping", "got 3"]),
    ],
)
def test_untagged_and_unknown_entries_name_the_entry_and_the_tags(entry, words):
    with pytest.raises(ScenarioError) as err:
        load_scenario("row1-optimal", f"{{faults: [!NoPath {{task: 1}}, {entry}]}}")
    message = str(err.value)
    assert message.startswith("--scenario-text: faults[1]: ") and "\n" not in message
    assert f"the tags are {TAGS}" in message
    for word in words:
        assert word in message, message


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{faults: [!GripperStuck {task: 1, after: 1.0}]}", r"faults\[0\]\.after: unknown key"),
        ("{faults: [!GripLost {kind: grip-lost, task: 1}]}", r"faults\[0\]\.kind: unknown key"),
        ("{motion: !MotionConfig {hold_time: 1}}", r"motion: a tag \(!MotionConfig\) chooses"),
        ("{faults: [!NoSeat {task: 1, after: -1}]}", r"faults\[0\] \(no-seat\): after -1\.0"),
        ("{faults: [!GripperStuck {task: 1, stuck: sideways}]}", "stuck 'sideways': give close"),
        (
            "{faults: [!TrackerLoss {task: 1, duration: -1}]}",
            r"faults\[0\] \(tracker-loss\): duration -1\.0 must be >= 0",
        ),
        ("{faults: [!TrackerLoss {task: 1, torque: 1}]}", r"faults\[0\]\.torque: unknown key"),
    ],
)
def test_a_kind_takes_only_its_own_parameters(text, message):
    with pytest.raises(ScenarioError, match=message) as err:
        load_scenario("row1-optimal", text)
    assert "\n" not in str(err.value)


# Drake's loader reads a dataclass's field types as written: this module postpones no
# annotations (`from __future__ import annotations` would make them strings).
@dataclass
class _A:
    x: int = 0
    y: int = 0


@dataclass
class _B:
    x: int = 0


@dataclass
class _Holder:
    one: _A | _B = field(default_factory=lambda: _A(y=5))
    maybe: _B | None = None


def test_a_tagged_variant_merges_onto_a_default_of_its_type_as_drake_does():
    for load in (
        lambda text: load_typed(_Holder, text=text),
        lambda text: yaml_load_typed(schema=_Holder, data=text),
    ):
        assert load("{one: !_A {x: 1}}").one == _A(x=1, y=5)
        assert load("{one: !_B {x: 2}}").one == _B(x=2)
        assert load("{maybe: {x: 3}}").maybe == _B(x=3)  # an optional section takes no tag
    with pytest.raises(TypedYamlError, match="one: untagged"):
        load_typed(_Holder, text="{one: {x: 1}}")  # Drake reads it as the first member


def test_tagged_text_is_written_back_with_its_tags():
    text = "{faults: [!GripLost {task: 2, after: 0.5}], motion: {hold_time: 1}}"
    assert dump_flow(load_tagged(text)) == text
    with pytest.raises(Exception, match="could not determine a constructor"):
        load_tagged("{a: !!python/object:os.system {}}")  # still a safe loader


def test_the_scenario_identity_tells_kinds_with_the_same_fields_apart():
    def identity(entry: str) -> ScenarioIdentity:
        return ScenarioIdentity.of(load_scenario("row1-optimal", f"{{faults: [{entry}]}}"))

    silent = identity("!OperatorSilent {task: 1}")
    assert not silent.matches(identity("!NoPath {task: 1, duration: 15.0}"))
    assert silent.matches(identity("!OperatorSilent {task: 1, duration: 15}"))
    assert silent.values["faults"] == [{"kind": "operator-silent", "task": 1, "duration": 15.0}]


def test_an_evaluation_override_keeps_its_fault_tags():
    """`evaluate --cell --scenario-text` writes its overrides into each run's one text: the
    tags stay, and the run's scenario has the faults."""
    from types import SimpleNamespace

    from hrc_drake.cell.run.evaluate import CellOptions
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    space = generate_states(load_spec(load_scenario("row1-optimal").assembly_path))
    delay = SimpleNamespace(distribution="lognormal", median=2.5, sigma=0.3)
    interaction = SimpleNamespace(mode="wait", interface="touch", delay=delay)
    # What `run_text` reads of an evaluation's Setup.
    run = {"operator_model": "follows", "params": {}, "seed": 3, "decider": "exact"}
    setup = SimpleNamespace(space=space, interaction=interaction, **run)
    faults = "{faults: [!GripLost {task: 2, after: 0.5}, !Pushed {task: 1}]}"
    text = CellOptions("row1-optimal", (LEAN, faults)).run_text(setup, 0)
    assert text.startswith("{faults: [!GripLost {task: 2, after: 0.5}, !Pushed {task: 1}], ")
    assert load_cell_scenario("row1-optimal", [LEAN, text]).faults == [
        GripLost(task=2, after=0.5),
        Pushed(task=1),
    ]
