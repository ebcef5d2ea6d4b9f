"""The live panel with no browser: its labels over the catalogue, its markers, and a live run
driven by button messages injected into Meshcat the way Drake's own tests press buttons (the
same code path as a click). The browser tests (`tests/test_browser.py`) click in Chromium."""

import base64
import re

import pytest
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform

from hrc_drake.hri.controls import control_name, is_safe_control_name
from hrc_drake.hri.live import ON_ITS_WAY, LiveOperator, describe_task, panel_buttons
from hrc_drake.resources import models_dir
from hrc_drake.tasks.graph import StateKind, generate_states
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

umsgpack = pytest.importorskip("umsgpack")

CATALOGUE = sorted((models_dir() / "assemblies").glob("*.yaml"))
# The in-process live runs, at ten times the wall clock's pace: their clicks are injected at
# simulated times, so the pace changes nothing they check (the browser tests run at 3).
FAST_PACE = 10.0


@pytest.mark.parametrize(
    ("text", "name"),
    [
        ("F1: the robot's proposal", "F1: the robots proposal"),
        ('say "F2"', "say F2"),
        ("a\\b", "a/b"),
        ("two\nlines", "two lines"),
        ("<b>bold</b> & co", "b bold /b co"),
        ("F1 - robot proposal", "F1 - robot proposal"),
        ("mistake: F03 lands in F02", "mistake: F03 lands in F02"),
    ],
)
def test_control_names_carry_no_quote_backslash_or_markup(text, name):
    assert control_name(text) == name
    assert is_safe_control_name(name)


def test_a_name_with_nothing_safe_in_it_is_refused():
    with pytest.raises(ValueError, match="nothing left"):
        control_name("'\"`")
    assert not is_safe_control_name("F1: the robot's proposal")


@pytest.mark.parametrize("path", CATALOGUE, ids=lambda p: p.stem)
def test_every_label_the_panel_makes_is_safe_for_every_catalogue_assembly(path):
    """Every state, with every feasible task as the proposal (whatever the policy): each label
    is safe, the proposal's button comes first and says so, and every feasible task has a
    button."""
    space = generate_states(load_spec(path))
    boundaries = 0
    for index in range(len(space.kind)):
        if space.kind[index] == StateKind.TERMINAL:
            continue
        state = space.sequence(index)
        feasible = [t for t, _ in space.tasks(index)]
        for proposal in feasible:
            buttons = panel_buttons(space, state, proposal)
            labels = list(buttons)
            assert all(is_safe_control_name(label) for label in labels), labels
            assert not any(c in label for label in labels for c in "'\"`\\"), labels
            assert labels[0] == f"{proposal} - robot proposal" and buttons[labels[0]] == proposal
            assert set(buttons.values()) == set(feasible), (state, proposal, buttons)
            assert describe_task(space, proposal, state).startswith(proposal)
            boundaries += 1
    assert boundaries > 0


def test_an_undo_proposal_shows_its_own_marker_and_the_buttons_go_after_the_click(flange_space):
    """At a dead end (F2 first: no correct assembly is left) the robot proposes undo: the red
    undo marker shows over the part, not the ghost of a placement; the panel offers undo as the
    robot's proposal, once; the click returns undo and takes the buttons down."""
    meshcat = Meshcat()
    seen = {}

    def visible(path: str) -> bool:
        return umsgpack.unpackb(meshcat._GetPackedProperty(path, "visible"))["value"]

    def click(prompt):
        seen["buttons"] = meshcat.GetButtonNames()
        seen["undo"], seen["proposal"] = (
            visible("/operator_choices/undo"),
            visible("/operator_choices/proposal"),
        )
        meshcat._InjectWebsocketMessage(
            umsgpack.packb({"type": "button", "name": _button_for(prompt, UNDO)})
        )

    said = []
    operator = LiveOperator(
        meshcat,
        flange_space,
        place=lambda task, state: RigidTransform([0.3, 0.08 * len(state), 0.0]),
        clock=lambda: 0.0,
        on_prompt=click,
        say=said.append,
    )
    assert operator(2, ("F2",), UNDO) == UNDO
    assert seen["buttons"] == ["undo - robot proposal"]
    assert seen["undo"] is True and seen["proposal"] is False
    assert meshcat.GetButtonNames() == [] and visible("/operator_choices/undo") is False
    assert meshcat.HasPath("/operator_choices/step_2")
    assert "undo: take F2 off" in said[0] and '"Open Controls", top right' in said[0]
    assert said[-1] == "step 2: you chose undo: take F2 off (the robot's proposal)"


@pytest.mark.slow
def test_a_live_run_follows_the_clicks_to_a_terminal_state(tmp_path, monkeypatch):
    """Row 4 clicked by hand: F3 instead of the proposed F1 at step 1, a second after the
    buttons came up, while the robot is already on its way with F1 (it re-targets); then the
    robot's proposals at once. The run ends on the minimum-effort column, and the recording
    shows the choices."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    row = load_cell_scenario("row4-forces-4", LEAN)
    clicks = {1: "F3"}
    prompts = []
    later = []  # (simulated time, Meshcat, message) of a click still to come

    def click(prompt):
        prompts.append(prompt)
        name = _button_for(prompt, clicks.get(prompt.step, prompt.proposal))
        message = umsgpack.packb({"type": "button", "name": name})
        # The live run goes on while the buttons are up: the first click comes a second
        # later (Meshcat takes injected messages on the simulation's thread only, so it is
        # pressed at the operator's first look after that; a browser's click comes any time).
        wait = 1.0 if prompt.step == 1 else 0.0
        later.append((prompt.sim_time + wait, prompt.meshcat, message))

    def poll(operator, prompt):
        for due, meshcat, message in list(later):
            if operator.clock() >= due:
                later.remove((due, meshcat, message))
                meshcat._InjectWebsocketMessage(message)
        return poll_now(operator, prompt)

    poll_now = LiveOperator.poll
    monkeypatch.setattr(LiveOperator, "poll", poll)

    # The clicks come at simulated times, so the run need not wait for the wall clock.
    result = run_scenario(
        row, live=True, on_prompt=click, record=tmp_path / "live.html", pace=FAST_PACE
    )
    assert result.error is None and result.done and not result.interrupted
    assert result.names == list(row.minimum_effort)
    assert [t.indicated for t in result.tasks] == ["F3", "S12", "F01"]
    assert [t.observed for t in result.tasks] == ["F3", "S12", "F01"]
    # The robot started on F1 with the buttons up, and the click re-targeted it on its way.
    first_task = result.tasks[0]
    assert first_task.committed == "F1" and first_task.retargeted
    assert first_task.indicated_at > 0.5
    # The panel offered the proposal first, saying the robot is on its way with it, the other
    # feasible tasks, and the spec's mistake.
    first = prompts[0]
    assert next(iter(first.buttons)) == "F1 - robot proposal" + ON_ITS_WAY
    assert {"F1", "F2", "F3", "S12", "S23"} <= set(first.buttons.values())
    assert "mistake: F01 lands in F02" in prompts[2].buttons
    # Choices are drawn into the recording (the panel is not part of it).
    commands = _recorded_commands((tmp_path / "live.html").read_text())
    for path in (b"operator_choices/step_1", b"operator_choices/proposal", b"safety/stopped"):
        assert path in commands, path


def _button_for(prompt, task: str) -> str:
    """The first button of the panel that performs `task`."""
    return next(name for name, performs in prompt.buttons.items() if performs == task)


def _recorded_commands(html: str) -> bytes:
    """The Meshcat commands a static page replays (base64 msgpack blobs), concatenated."""
    blobs = re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)
    return b"".join(base64.b64decode(blob) for blob in blobs)


def test_the_catalogue_is_there():
    """The label test above runs over the catalogue: it must not be empty."""
    assert {"flange", "four-slot", "five-slot", "three-oval"} <= {p.stem for p in CATALOGUE}


@pytest.mark.parametrize("port", ["80", "70000", "taken"])
def test_a_port_meshcat_cannot_serve_is_a_one_line_error(capsys, port):
    """`--port` is checked before the run: Drake's Meshcat takes 0 or 1024-65535, and a port
    another program holds cannot be served."""
    import socket

    from hrc_drake.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("", 0))
        holder.listen()
        if port == "taken":
            port = str(holder.getsockname()[1])
        code = main(["simulate", "--live", "--lean", "--port", port])
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        code == 2
        and len(err) == 1
        and err[0].startswith(f"hrc-drake simulate: error: --port {port}:")
    )


def _press(meshcat, name: str) -> None:
    """A click on the button `name`, as the browser sends it."""
    meshcat._InjectWebsocketMessage(umsgpack.packb({"type": "button", "name": name}))


def test_a_question_asked_again_is_sent_afresh_and_a_click_after_it_counts(flange_space):
    """The Supervisor asks again (the prompt's `asked` one up): the terminal says so and the
    buttons are deleted and added again (a browser that missed them gets them); a click before
    the question is not its answer, one after the re-ask is; a button deleted by another hand
    is added again instead of failing the run."""
    from hrc_drake.hri.messages import Prompt, PromptKind

    meshcat, said = Meshcat(), []
    operator = LiveOperator(
        meshcat,
        flange_space,
        place=lambda task, state: RigidTransform([0.3, 0.0, 0.0]),
        clock=lambda: 0.0,
        say=said.append,
    )
    # A click on a name left over from before the question does not answer it.
    meshcat.AddButton("F1 - robot proposal")
    _press(meshcat, "F1 - robot proposal")
    prompt = Prompt(1, PromptKind.CHOOSE, (), "F1")
    assert operator.poll(prompt) is None
    assert "F1 - robot proposal" in meshcat.GetButtonNames()
    meshcat.DeleteButton("F2 instead")  # gone from the panel: added again, not an error
    assert operator.poll(prompt) is None and "F2 instead" in meshcat.GetButtonNames()
    again = Prompt(1, PromptKind.CHOOSE, (), "F1", asked=1)
    assert operator.poll(again) is None
    assert "still no answer (asked again, 1 time)" in said[-1]
    _press(meshcat, "F2 instead")
    assert operator.poll(again) == "F2"
    assert meshcat.GetButtonNames() == []


def test_a_task_handed_over_is_confirmed_with_one_button(flange_space):
    """A `HANDOVER` shows "I did F1" and says why; the click returns the task and takes the
    button down."""
    from hrc_drake.hri.messages import Prompt, PromptKind

    meshcat, said = Meshcat(), []
    operator = LiveOperator(
        meshcat,
        flange_space,
        place=lambda task, state: None,
        clock=lambda: 0.0,
        say=said.append,
    )
    prompt = Prompt(1, PromptKind.HANDOVER, (), "F1", "oval_flange_1", reason="it lies tilted")
    assert operator.poll(prompt) is None
    assert meshcat.GetButtonNames() == ["I did F1"]
    assert "hands F1: oval flange on slot 1 over to you (it lies tilted)" in said[-1]
    _press(meshcat, "I did F1")
    assert operator.poll(prompt) == "F1" and meshcat.GetButtonNames() == []


@pytest.mark.slow
def test_a_live_prompt_nobody_answers_ends_the_run_after_the_give_up(tmp_path, capsys):
    """Nobody clicks: the robot asks again every `run.indication_timeout` (the terminal says
    so) and after `run.indication_give_up` the run ends, not terminal, with a one-line reason,
    its JSON and its recording written."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    text = "{run: {indication_timeout: 1, indication_give_up: 2.5}}"
    row = load_cell_scenario("row1-optimal", [LEAN, text])
    result = run_scenario(row, live=True, record=tmp_path / "live.html")
    report = result.to_json()
    assert report["terminal"] is False and not report["interrupted"]
    assert "no indication from the operator in 2.5 s" in report["error"]
    assert "run.indication_give_up" in report["error"] and "\n" not in report["error"]
    assert report["steps"] == [] and report["sim_time"] < 3.5
    assert (tmp_path / "live.html").stat().st_size > 100_000
    err = capsys.readouterr().err
    assert "still no answer (asked again, 2 times)" in err


@pytest.mark.slow
def test_a_live_run_goes_on_once_the_person_says_they_did_the_task_handed_over(monkeypatch):
    """The grip is lost in the first carry and the robot may not pick the part again
    (`run.recover_tries: 0`): it hands F1 over, the panel shows "I did F1", and once the person
    clicks it the run goes on to a terminal state, the step counted as handed over."""
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    text = "{run: {recover_tries: 0}, faults: [!GripLost {task: 1}]}"
    row = load_cell_scenario("row1-optimal", [LEAN, text])
    shown, later = [], []

    def click(prompt):
        shown.append(prompt)
        name = next(iter(prompt.buttons))  # the proposal, or "I did F1"
        later.append((prompt.sim_time + 1.0, _press, prompt.meshcat, name))

    def poll(operator, prompt):
        for item in list(later):
            due, press, meshcat, name = item
            if operator.clock() >= due:
                later.remove(item)
                press(meshcat, name)
        return poll_now(operator, prompt)

    poll_now = LiveOperator.poll
    monkeypatch.setattr(LiveOperator, "poll", poll)
    result = run_scenario(row, live=True, on_prompt=click, pace=FAST_PACE)
    assert result.done and result.error is None, result.error
    assert [bool(t.handed_over) for t in result.tasks] == [True, False, False]
    assert "slipped out of the gripper 1 time;" in result.tasks[0].handed_over
    handover = next(p for p in shown if list(p.buttons) == ["I did F1"])
    assert handover.step == 1 and result.to_json()["handovers"] == 1


class _Pendant:
    """The unlock button alone in a diagram, its `safety.mode` input exported (fixed by the
    test), sampled half a period after each update."""

    PERIOD = 0.02
    WAIT = 0.1  # s: the stop's unlock wait, said in the terminal

    def __init__(self, mode_connected: bool = True):
        from pydrake.systems.analysis import Simulator
        from pydrake.systems.framework import DiagramBuilder

        from hrc_drake.hri.pendant import UnlockButton

        self.meshcat, self.said = Meshcat(), []
        builder = DiagramBuilder()
        self.button = builder.AddSystem(
            UnlockButton(self.meshcat, self.PERIOD, self.WAIT, say=self.said.append)
        )
        builder.ExportOutput(self.button.GetOutputPort("safety.unlock"), "safety.unlock")
        if mode_connected:
            builder.ExportInput(self.button.GetInputPort("safety.mode"), "safety.mode")
        self.diagram = builder.Build()
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        self.k = 0
        if mode_connected:
            self.set_mode(1)

    def set_mode(self, mode: int) -> None:
        self.diagram.GetInputPort("safety.mode").FixValue(self.context, [float(mode)])

    def run(self, periods: int) -> list[float]:
        """The pulse output over the next `periods` updates."""
        out = []
        for _ in range(periods):
            self.simulator.AdvanceTo((self.k + 0.5) * self.PERIOD)
            self.k += 1
            out.append(self.diagram.GetOutputPort("safety.unlock").Eval(self.context)[0])
        return out


def test_the_unlock_button_is_up_only_in_a_protective_stop_and_pulses_once_per_click():
    """With the station's `safety.mode` connected: no button (and no pulse for a click on a
    name left over) outside a protective stop; in one, the button is up, the terminal says what
    to do, and each click is one pulse of one period, two quick clicks two pulses with a 0
    between; the end of the stop's unlock wait and a pulse that did not unlock are said; once
    the stop ends the button goes."""
    from hrc_drake.hri.pendant import UNLOCK_LABEL

    pendant = _Pendant()
    meshcat = pendant.meshcat
    assert is_safe_control_name(UNLOCK_LABEL) and UNLOCK_LABEL == "Unlock protective stop"
    assert pendant.run(5) == [0.0] * 5 and meshcat.GetButtonNames() == []
    meshcat.AddButton(UNLOCK_LABEL)  # a click before the stop is no unlock in it
    _press(meshcat, UNLOCK_LABEL)
    pendant.set_mode(3)
    assert pendant.run(3) == [0.0] * 3
    assert meshcat.GetButtonNames() == [UNLOCK_LABEL]
    assert pendant.said[-1].startswith("protective stop at 0.1")
    assert f'click "{UNLOCK_LABEL}" under "Open Controls"' in pendant.said[-1]
    _press(meshcat, UNLOCK_LABEL)
    assert pendant.run(6) == [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert "still in the protective stop" in pendant.said[-1]  # the stop went on
    assert 'protective stop: 0.1 s have passed; click "Unlock protective stop"' in pendant.said[-2]
    _press(meshcat, UNLOCK_LABEL)
    _press(meshcat, UNLOCK_LABEL)
    assert pendant.run(6) == [1.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    assert pendant.button.state(pendant.button.GetMyContextFromRoot(pendant.context)).pulses == 3
    pendant.set_mode(1)  # unlocked
    assert pendant.run(2) == [0.0, 0.0]
    assert pendant.said[-1].startswith("protective stop unlocked at")
    assert meshcat.GetButtonNames() == []


def test_the_unlock_button_without_the_mode_is_always_up_and_goes_when_closed():
    """Unconnected `safety.mode`: the button is up from the first update and every click is a
    pulse; `close` (the end of a run) takes it out of the panel."""
    from hrc_drake.hri.pendant import UNLOCK_LABEL

    pendant = _Pendant(mode_connected=False)
    assert pendant.run(2) == [0.0, 0.0]
    assert pendant.meshcat.GetButtonNames() == [UNLOCK_LABEL]
    _press(pendant.meshcat, UNLOCK_LABEL)
    assert pendant.run(4) == [1.0, 0.0, 0.0, 0.0]
    pendant.meshcat.DeleteButton(UNLOCK_LABEL)  # gone by another hand: up again, no pulse
    assert pendant.run(2) == [0.0, 0.0] and pendant.meshcat.GetButtonNames() == [UNLOCK_LABEL]
    _press(pendant.meshcat, UNLOCK_LABEL)
    assert pendant.run(3) == [1.0, 0.0, 0.0]
    pendant.button.close()
    assert pendant.meshcat.GetButtonNames() == [] and pendant.said == []


@pytest.mark.slow
def test_a_live_closed_loop_holds_a_protective_stop_until_the_unlock_click():
    """Row 1 live with a protective stop 1 s into task 1, simulated as fast as it goes (the
    loop stepped by hand, not paced): the station's `safety.unlock` is the button's, so the
    simulated operator does not unlock; the stop holds well past its 5 s wait with the button
    up, one click unlocks it, and the run ends terminal. A run that is not live leaves the
    input unconnected."""
    from hrc_drake.cell.run.run import build_closed_loop
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario
    from hrc_drake.hri.pendant import UNLOCK_LABEL

    text = "{faults: [!ProtectiveStop {task: 1, after: 1.0, duration: 0.5}]}"
    row = load_cell_scenario("row1-optimal", [LEAN, text])
    meshcat = Meshcat()

    def agree(prompt):
        _press(prompt.meshcat, next(iter(prompt.buttons)))

    loop = build_closed_loop(row, meshcat=meshcat, live=True, on_prompt=agree)
    station = loop.cell.diagram
    station_context = station.GetMyContextFromRoot(loop.root_context)

    def mode() -> int:
        return round(station.GetOutputPort("safety.mode").Eval(station_context)[0])

    loop.start()
    assert station.GetInputPort("safety.unlock").HasValue(station_context)
    while mode() != 3:
        assert loop.root_context.get_time() < 20.0, "no protective stop"
        loop.advance_to(loop.root_context.get_time() + 0.1)
    stopped_at = loop.root_context.get_time()
    loop.advance_to(stopped_at + 8.0)  # past the 5 s wait and the simulated operator's 1 s
    assert mode() == 3 and meshcat.GetButtonNames() == [UNLOCK_LABEL]
    _press(meshcat, UNLOCK_LABEL)
    loop.advance_to(loop.root_context.get_time() + 0.1)
    assert mode() != 3 and UNLOCK_LABEL not in meshcat.GetButtonNames()
    loop.advance_to(row.run.max_sim_time)
    result = loop.result()
    assert result.done and result.error is None, result.error
    function = result.safety_function
    assert (function.protective_stops, function.unlocks) == (1, 1)
    fault = result.to_json()["faults"][0]
    assert fault["kind"] == "protective-stop" and fault["recovered"], fault
    assert fault["seconds_lost"] > 8.0, fault

    quiet = build_closed_loop(row, meshcat=Meshcat())
    quiet.start()
    side = quiet.cell.diagram
    assert quiet.pendant is None
    assert not side.GetInputPort("safety.unlock").HasValue(
        side.GetMyContextFromRoot(quiet.root_context)
    )
