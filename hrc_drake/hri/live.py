"""A person as the operator, in the browser: Meshcat buttons at every task boundary.

`LiveOperator` is an operator callable (`hrc_drake.tasks.decide.Operator`) for the cell's
Supervisor. At a task boundary it shows the robot's proposal in the scene — a translucent ghost
of the part at the proposed place — and puts one button per feasible task in Meshcat's control
panel (the paper's touch menu: the proposal first, named as such), plus "mistake" (the part goes
to the spec's mistaken alternative, the other row) and "undo" when they apply. It blocks the
Supervisor's decision until a button is clicked, then draws the choice into the scene at the
current simulated time (`time_in_recording`), so that a recording of the live run shows it: the
control panel is not part of a recording.

Tests press buttons with no browser, as Drake's own tests do (the same code path as a click):
`meshcat._InjectWebsocketMessage(umsgpack.packb({"type": "button", "name": NAME}))`, from the
`on_prompt` hook that the operator calls once the buttons are up.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform

from hrc_drake.hri.operator import StochasticOperator
from hrc_drake.tasks.graph import StateSpace
from hrc_drake.tasks.tokens import UNDO

ROOT = "/operator_choices"
GHOST = Rgba(0.2, 0.6, 1.0, 0.35)
CONFIRMED = Rgba(0.1, 0.8, 0.2, 0.9)
OVERRIDDEN = Rgba(1.0, 0.55, 0.0, 0.9)
PART_BOX = (0.09, 0.06, 0.02)  # m; the ghost's size (the flanges' envelope)


@dataclass(frozen=True)
class Prompt:
    """What the person is asked at a task boundary: `buttons` maps each button's name (its
    label in the panel) to the task it performs; `meshcat` shows them."""

    step: int
    state: tuple[str, ...]
    proposal: str
    buttons: dict[str, str]
    sim_time: float
    meshcat: Meshcat

    def button_for(self, task: str) -> str:
        """The name of the button that performs `task` (KeyError naming the offered tasks)."""
        for name, t in self.buttons.items():
            if t == task:
                return name
        raise KeyError(
            f"no button performs {task!r}; offered: {sorted(set(self.buttons.values()))}"
        )


class LiveOperator:
    """The operator is whoever clicks the Meshcat buttons (see the module docstring).

    Args:
        meshcat: the cell's Meshcat.
        space: the assembly's state space (feasible tasks, the spec's mistakes).
        place: `(task, state) -> RigidTransform | None`, where the part of `task` would sit.
        clock: the simulated time now (for `time_in_recording`).
        on_prompt: called with the `Prompt` once the buttons are shown (tests inject clicks).
        after_answer: called after each answer (the runner resets the real-time pacing).
        poll: seconds between looks at the button counts.
    """

    def __init__(
        self,
        meshcat: Meshcat,
        space: StateSpace,
        place: Callable[[str, tuple[str, ...]], RigidTransform | None],
        clock: Callable[[], float],
        on_prompt: Callable[[Prompt], None] | None = None,
        after_answer: Callable[[], None] | None = None,
        poll: float = 0.05,
    ):
        self.meshcat, self.space, self.place, self.clock = meshcat, space, place, clock
        self.on_prompt, self.after_answer, self.poll = on_prompt, after_answer, poll
        self._mistakes = StochasticOperator(space, 0.0, 0.0)
        self.answers: list[tuple[int, str, str]] = []  # (step, proposal, task chosen)
        meshcat.SetObject(f"{ROOT}/ghost", Box(*PART_BOX), GHOST)
        meshcat.SetProperty(f"{ROOT}/ghost", "visible", False, 0.0)

    def buttons(self, state: tuple[str, ...], proposal: str) -> dict[str, str]:
        """Button name -> task for a boundary: the proposal first, the other feasible tasks,
        the mistaken alternative of the proposal, undo."""
        feasible = [t for t, _ in self.space.tasks(self.space.index(state))]
        buttons = {}
        if proposal in feasible:
            buttons[f"{proposal}: the robot's proposal"] = proposal
        for task in feasible:
            if task not in (proposal, UNDO):
                buttons[f"{task} instead"] = task
        alternatives = self._mistakes.alternatives(state, proposal)
        if alternatives:
            buttons[f"mistake: {proposal} lands in {alternatives[0]}"] = alternatives[0]
        if UNDO in feasible:
            buttons["undo the last part"] = UNDO
        return buttons

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        """Show the proposal and the buttons; block until a click; return the task chosen."""
        now = self.clock()
        buttons = self.buttons(state, proposal)
        ghost = self.place(proposal, state) if proposal != UNDO else None
        if ghost is not None:
            self.meshcat.SetTransform(f"{ROOT}/ghost", ghost, now)
            self.meshcat.SetProperty(f"{ROOT}/ghost", "visible", True, now)
        base = {}
        for name in buttons:
            self.meshcat.AddButton(name)
            base[name] = self.meshcat.GetButtonClicks(name)
        print(f"step {step}: the robot proposes {proposal}; click a button in Meshcat", flush=True)
        if self.on_prompt is not None:
            self.on_prompt(Prompt(step, state, proposal, dict(buttons), now, self.meshcat))
        chosen = None
        while chosen is None:
            for name in buttons:
                if self.meshcat.GetButtonClicks(name) > base[name]:
                    chosen = buttons[name]
                    break
            else:
                time.sleep(self.poll)
        for name in buttons:
            self.meshcat.DeleteButton(name)
        self._draw_choice(step, state, proposal, chosen, now)
        self.answers.append((step, proposal, chosen))
        if self.after_answer is not None:
            self.after_answer()
        return chosen

    def _draw_choice(self, step, state, proposal, chosen, now) -> None:
        """The ghost goes; a marker at the chosen place stays (green: the proposal confirmed,
        orange: another task), from `now` on in the recording."""
        self.meshcat.SetProperty(f"{ROOT}/ghost", "visible", False, now)
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


__all__ = ["LiveOperator", "Prompt"]
