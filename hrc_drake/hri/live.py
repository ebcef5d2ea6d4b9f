"""A person as the operator, in the browser: Meshcat buttons at every task boundary.

`LiveOperator` is the operator for the cell's simulated station. At a task boundary it shows the
robot's proposal in the scene and puts one button per choice in Meshcat's control panel (the
paper's touch menu). In the cell it is asked without blocking (`poll`, once per station update):
the simulation goes on in real time while the buttons are up, so a robot that anticipates moves
on its commitment, and the click is the indication whenever it comes. (Called as an operator
callable, `hrc_drake.tasks.decide.Operator`, it blocks until a click.) The buttons:
- the proposal's button first, "F1 - robot proposal" (names are made safe for Meshcat's
  JavaScript by `hrc_drake.hri.controls`, which drops the apostrophe of "robot's");
- the button of the task the robot has already started on, if any, says so: "F1 - robot
  proposal, robot on its way" (the prompt's `committed`);
- "F2 instead" for every other feasible task;
- "mistake: F03 lands in F02" when the spec lists a mistake for the proposal (the part goes to
  the mistaken alternative, the other row);
- "undo the last part" when undo is feasible and not the proposal.
When the robot hands a task over (a `HANDOVER` prompt: it cannot do it, e.g. a part it dropped
and cannot pick again), the panel shows one button, "I did F1", and the terminal says what to
do and why: the person does the task by hand, clicks, and the run goes on.

A question left unanswered is asked again (the Supervisor's prompt comes back with its `asked`
count one up, every `run.indication_timeout`): the terminal says so and the panel's buttons are
deleted and added afresh, so that a browser that missed them (or a click lost on its way) gets
them again. (Drake's `Meshcat.AddButton` of a name already registered only resets its count and
sends nothing to the browser: a button is re-sent only by deleting it first.) Clicks are read
against each button's count when it was shown; a button found missing is added again rather
than failing the run. After `run.indication_give_up` the Supervisor gives up and the run ends.

In the scene, a proposed placement shows as a translucent blue ghost of the part at its place
with a blue cone pointing down at it; a proposed undo as a red ghost over the last part placed
with a red cone pointing up (the part comes off). Once a button is clicked the marker goes and a
sphere above the chosen place stays (green: the proposal confirmed, orange: another task), all
drawn at the simulated time (`time_in_recording`), so that a recording of the live run shows
them: the control panel is not part of a recording.

The browser tests click these buttons in Chromium (`tests/test_browser.py`); the fast unit test
presses them with no browser, as Drake's own tests do (the same code path as a click):
`meshcat._InjectWebsocketMessage(umsgpack.packb({"type": "button", "name": NAME}))`, from the
`on_prompt` hook that the operator calls once the buttons are up.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, Meshcat, MeshcatCone, Rgba, Sphere
from pydrake.math import RigidTransform, RotationMatrix

from hrc_drake.hri.controls import add_button, control_name
from hrc_drake.hri.messages import Prompt, PromptKind
from hrc_drake.hri.operator import StochasticOperator
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO

ROOT = "/operator_choices"
PROPOSAL_MARK = f"{ROOT}/proposal"  # the ghost of a proposed placement and its cone
UNDO_MARK = f"{ROOT}/undo"  # the ghost of the part a proposed undo takes off and its cone
GHOST = Rgba(0.2, 0.6, 1.0, 0.5)
POINTER = Rgba(0.2, 0.6, 1.0, 0.9)
UNDO_GHOST = Rgba(0.9, 0.15, 0.1, 0.5)
UNDO_POINTER = Rgba(0.9, 0.15, 0.1, 0.9)
CONFIRMED = Rgba(0.1, 0.8, 0.2, 0.9)
OVERRIDDEN = Rgba(1.0, 0.55, 0.0, 0.9)
PART_BOX = (0.09, 0.06, 0.02)  # m; the ghost's size (the flanges' envelope)
CONE = (0.06, 0.022)  # m; the pointer cone's height and radius
CONE_GAP = 0.03  # m; from the part's frame to the cone's tip (proposal) or base (undo)
WHERE_THE_BUTTONS_ARE = '"Open Controls", top right of the Meshcat page'


@dataclass(frozen=True)
class PanelPrompt:
    """What the person is asked at a task boundary: `buttons` maps each button's name (its
    label in the panel, in the panel's order) to the task it performs; `meshcat` shows them."""

    step: int
    state: tuple[str, ...]
    proposal: str
    buttons: dict[str, str]
    sim_time: float
    meshcat: Meshcat


ON_ITS_WAY = ", robot on its way"  # the label's end on the task the robot started on


def panel_buttons(
    space: StateSpace, state: tuple[str, ...], proposal: str, committed: str = ""
) -> dict[str, str]:
    """Button name -> task for a task boundary, in the panel's order: the proposal first, the
    other feasible tasks, the proposal's mistaken alternative (the spec's `mistakes`), undo; the
    task the robot has started on (`committed`, "" for none) says so. Every name is made safe
    for Meshcat (`control_name`); ValueError if two choices would get the same name."""
    feasible = [t for t, _ in space.tasks(space.index(state))]
    labelled: list[tuple[str, str]] = []
    if proposal in feasible:
        labelled.append((f"{proposal} - robot proposal", proposal))
    labelled += [(f"{t} instead", t) for t in feasible if t not in (proposal, UNDO)]
    labelled = [
        (label + ON_ITS_WAY if task == committed else label, task) for label, task in labelled
    ]
    alternatives = StochasticOperator(space, 0.0, 0.0).alternatives(state, proposal)
    if alternatives:
        labelled.append((f"mistake: {proposal} lands in {alternatives[0]}", alternatives[0]))
    if UNDO in feasible and proposal != UNDO:
        labelled.append(("undo the last part", UNDO))
    buttons: dict[str, str] = {}
    for label, task in labelled:
        name = control_name(label)
        if name in buttons:
            raise ValueError(
                f"two buttons would both read {name!r} ({buttons[name]} and {task}); give the "
                "assembly's parts symbols that differ in letters or digits"
            )
        buttons[name] = task
    return buttons


def describe_task(space: StateSpace, task: str, state: tuple[str, ...]) -> str:
    """The task in words, e.g. "F1: oval flange on slot 1", "undo: take F2 off"."""
    spec = space.spec
    if task == UNDO:
        return f"undo: take {state[-1]} off" if state else "undo"
    placement = spec.placement(task)
    name = spec.part(placement.part).name
    slots = ", ".join(str(s) for s in placement.slots)
    where = f"slot{'s' if len(placement.slots) > 1 else ''} {slots}"
    if placement.host is not None:
        where = f"the {spec.part(placement.host).name} over {where}"
    return f"{task}: {name} on {where}"


def live_banner(url: str) -> str:
    """What the terminal says when a live run starts: where the page and its buttons are."""
    return (
        f"live: open {url} in a web browser; at every task boundary the robot shows its "
        "proposal in the scene (and, anticipating, starts on it) and takes your click under "
        f"{WHERE_THE_BUTTONS_ARE} as the target"
    )


@dataclass
class _Shown:
    """The buttons up for a question (a step's `CHOOSE` or `HANDOVER`): name -> task, each
    button's clicks when it was shown, the proposal's marker in the scene (None: nothing
    shown) and how often the question had been asked again then."""

    step: int
    buttons: dict[str, str]
    clicks: dict[str, int]
    marker: str | None
    kind: PromptKind = PromptKind.CHOOSE
    asked: int = 0


class LiveOperator:
    """The operator is whoever clicks the Meshcat buttons (see the module docstring).

    Args:
        meshcat: the cell's Meshcat.
        space: the assembly's state space (feasible tasks, the spec's mistakes).
        place: `(task, state) -> RigidTransform | None`, where the part of `task` would sit.
        clock: the simulated time now (for `time_in_recording`).
        on_prompt: called with the `PanelPrompt` once the buttons are shown (tests inject
            clicks).
        after_answer: called after each answer (the runner resets the real-time pacing).
        poll: seconds between looks at the button counts.
        say: where the prompt for the person in the terminal goes (default: stderr, so that
            `simulate --json` keeps stdout for its JSON).
    """

    def __init__(
        self,
        meshcat: Meshcat,
        space: StateSpace,
        place: Callable[[str, tuple[str, ...]], RigidTransform | None],
        clock: Callable[[], float],
        on_prompt: Callable[[PanelPrompt], None] | None = None,
        after_answer: Callable[[], None] | None = None,
        poll: float = 0.05,
        say: Callable[[str], None] | None = None,
    ):
        self.meshcat, self.space, self.place, self.clock = meshcat, space, place, clock
        self.on_prompt, self.after_answer, self.poll_period = on_prompt, after_answer, poll
        self._shown: _Shown | None = None  # the step whose buttons are up
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self.answers: list[tuple[int, str, str]] = []  # (step, proposal, task chosen)
        _add_marker(meshcat, PROPOSAL_MARK, GHOST, POINTER)
        _add_marker(meshcat, UNDO_MARK, UNDO_GHOST, UNDO_POINTER)

    def buttons(self, state: tuple[str, ...], proposal: str, committed: str = "") -> dict[str, str]:
        """Button name -> task for a boundary (`panel_buttons`)."""
        return panel_buttons(self.space, state, proposal, committed)

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        """Show the proposal and the buttons; block until a click; return the task chosen."""
        prompt = Prompt(step, PromptKind.CHOOSE, state, proposal)
        try:
            while (chosen := self.poll(prompt)) is None:
                time.sleep(self.poll_period)
        finally:
            self.close()
        if self.after_answer is not None:
            self.after_answer()
        return chosen

    def poll(self, prompt: Prompt) -> str | None:
        """The task clicked for `prompt` (a `CHOOSE`; for a `HANDOVER`, its task once the
        person says they did it), or None while no button is clicked: the first call of a
        question shows it, a call for a question asked again shows it afresh (after a last look
        for a click), and the one that finds a click takes the buttons down."""
        shown = self._shown
        if shown is None or (shown.step, shown.kind) != (prompt.step, prompt.kind):
            self.close()
            self._show(prompt)
        elif prompt.asked > shown.asked:
            chosen = self._clicked(prompt)
            if chosen is not None:
                return chosen
            self._ask_again(prompt)
        return self._clicked(prompt)

    def _clicked(self, prompt: Prompt) -> str | None:
        """The task of the first button clicked since it was shown (and the click's marks),
        or None."""
        shown = self._shown
        for name, task in shown.buttons.items():
            if self._clicks(name) > shown.clicks[name]:
                if prompt.kind == PromptKind.HANDOVER:
                    self.close()
                    self.say(f"step {prompt.step}: you did {task}; the robot goes on")
                else:
                    self._answered(prompt, task)
                return task
        return None

    def _clicks(self, name: str) -> int:
        """The button's click count; a button that has gone from the panel (deleted by
        another hand) is added again, counted from there."""
        try:
            return self.meshcat.GetButtonClicks(name)
        except RuntimeError:
            add_button(self.meshcat, name)
            self._shown.clicks[name] = self.meshcat.GetButtonClicks(name)
            return self._shown.clicks[name]

    def _ask_again(self, prompt: Prompt) -> None:
        """The question is asked again: say so, and send its buttons to the browser afresh
        (deleted first: re-adding a registered name sends nothing)."""
        shown = self._shown
        for name in shown.buttons:
            self.meshcat.DeleteButton(name, strict=False)
            add_button(self.meshcat, name)
            shown.clicks[name] = self.meshcat.GetButtonClicks(name)
        shown.asked = prompt.asked
        self.say(
            f"step {prompt.step}: still no answer (asked again, {prompt.asked} time"
            f"{'s' if prompt.asked > 1 else ''}); the buttons are shown afresh: "
            + self.question_text(prompt, shown.buttons)
        )

    def close(self) -> None:
        """Take down the buttons of a step still unanswered (a run that ends or is stopped
        leaves none in the panel)."""
        if self._shown is not None:
            for name in self._shown.clicks:
                self.meshcat.DeleteButton(name, strict=False)
            self._shown = None

    def handover_buttons(self, prompt: Prompt) -> dict[str, str]:
        """Button name -> task for a task handed over: one, "I did F1"."""
        return {control_name(f"I did {prompt.proposal}"): prompt.proposal}

    def question_text(self, prompt: Prompt, buttons: dict[str, str]) -> str:
        """What the terminal says of a question: a proposal (`prompt_text`) or a task handed
        over, what to do and why."""
        if prompt.kind != PromptKind.HANDOVER:
            text = self.prompt_text(prompt.step, prompt.state, prompt.proposal, buttons)
            if prompt.committed:
                text += f"; the robot is already on its way with {prompt.committed}"
            return text
        task = describe_task(self.space, prompt.proposal, prompt.state)
        why = f" ({prompt.reason})" if prompt.reason else ""
        return (
            f"step {prompt.step}: the robot hands {task} over to you{why}; do it by hand, then "
            f'click "{next(iter(buttons))}" under {WHERE_THE_BUTTONS_ARE}'
        )

    def _show(self, prompt: Prompt) -> None:
        now = self.clock()
        if prompt.kind == PromptKind.HANDOVER:
            buttons, mark = self.handover_buttons(prompt), None
        else:
            buttons = self.buttons(prompt.state, prompt.proposal, prompt.committed)
            mark = self._show_proposal(prompt.state, prompt.proposal, now)
        base = {}
        for text in buttons:
            name = add_button(self.meshcat, text)
            # Counted from here: a name left registered is reset by AddButton, and a click
            # that came before the question is not an answer to it.
            base[name] = self.meshcat.GetButtonClicks(name)
        self._shown = _Shown(prompt.step, buttons, base, mark, prompt.kind, prompt.asked)
        self.say(self.question_text(prompt, buttons))
        if self.on_prompt is not None:
            self.on_prompt(
                PanelPrompt(
                    prompt.step, prompt.state, prompt.proposal, dict(buttons), now, self.meshcat
                )
            )

    def _answered(self, prompt: Prompt, chosen: str) -> None:
        """The click's marks: the proposal's marker goes, the choice's stays."""
        mark = self._shown.marker
        self.close()
        if mark is not None:
            self.meshcat.SetProperty(mark, "visible", False, self.clock())
        self._draw_choice(prompt.step, prompt.state, prompt.proposal, chosen, self.clock())
        self.answers.append((prompt.step, prompt.proposal, chosen))
        # The terminal confirms the click (a person sees it taken; a log shows which).
        agreed = "the robot's proposal" if chosen == prompt.proposal else "instead of the proposal"
        self.say(
            f"step {prompt.step}: you chose {describe_task(self.space, chosen, prompt.state)} "
            f"({agreed})"
        )

    def prompt_text(
        self, step: int, state: tuple[str, ...], proposal: str, buttons: dict[str, str]
    ) -> str:
        """What the terminal says at a boundary: the proposal in words and where to answer."""
        marker = "red" if proposal == UNDO else "blue"
        first = next(iter(buttons), None)
        agree = f'click "{first}" to agree, or another button' if first else "click a button"
        return (
            f"step {step}: the robot proposes {describe_task(self.space, proposal, state)} "
            f"({marker} marker in the scene); {agree} under {WHERE_THE_BUTTONS_ARE}"
        )

    def _show_proposal(self, state, proposal, now) -> str | None:
        """Put the proposal's marker in the scene from `now` on; returns its path (None: no
        place to show)."""
        if proposal == UNDO:
            path = UNDO_MARK
            where = self.place(state[-1], state[:-1]) if state else None
        else:
            path = PROPOSAL_MARK
            where = self.place(proposal, state)
        if where is None:
            return None
        _place_marker(self.meshcat, path, where, now, pointing_down=proposal != UNDO)
        self.meshcat.SetProperty(path, "visible", True, now)
        return path

    def _draw_choice(self, step, state, proposal, chosen, now) -> None:
        """A marker at the chosen place stays (green: the proposal confirmed, orange: another
        task), from `now` on in the recording."""
        where = self.place(chosen, state) if chosen != UNDO else None
        path = f"{ROOT}/step_{step}"
        colour = CONFIRMED if chosen == proposal else OVERRIDDEN
        if where is None:  # undo: a marker above the plate's last part is enough
            where = self.place(state[-1], state[:-1]) if state else None
        if where is None:
            return
        self.meshcat.SetObject(path, Sphere(0.012), colour)
        marker = RigidTransform(where.translation() + np.array([0.0, 0.0, 0.06]))
        self.meshcat.SetTransform(path, marker, now)
        self.meshcat.SetProperty(path, "visible", False, 0.0)
        self.meshcat.SetProperty(path, "visible", True, now)


def _add_marker(meshcat: Meshcat, path: str, ghost: Rgba, pointer: Rgba) -> None:
    """A hidden marker: a ghost of a part and a cone above it."""
    meshcat.SetObject(f"{path}/ghost", Box(*PART_BOX), ghost)
    meshcat.SetObject(f"{path}/cone", MeshcatCone(CONE[0], CONE[1], CONE[1]), pointer)
    meshcat.SetProperty(path, "visible", False, 0.0)


def _place_marker(
    meshcat: Meshcat, path: str, X_W_part: RigidTransform, now: float, pointing_down: bool
) -> None:
    """The ghost at the part's pose; the cone above it, its tip down at the part (a proposed
    placement) or up, away from it (a proposed undo)."""
    meshcat.SetTransform(f"{path}/ghost", X_W_part, now)
    # The cone's tip is its frame's origin and it opens along +z; turned over, it points up.
    up = np.array([0.0, 0.0, 1.0])
    p = X_W_part.translation()
    if pointing_down:
        X_W_cone = RigidTransform(p + CONE_GAP * up)
    else:
        flipped = RotationMatrix.MakeXRotation(np.pi)
        X_W_cone = RigidTransform(flipped, p + (CONE_GAP + CONE[0]) * up)
    meshcat.SetTransform(f"{path}/cone", X_W_cone, now)


__all__ = [
    "ON_ITS_WAY",
    "LiveOperator",
    "PanelPrompt",
    "describe_task",
    "live_banner",
    "panel_buttons",
]
