"""The teach pendant's unlock in the browser: a Meshcat button that unlocks a protective stop.

A UR in a protective stop holds until its cause has cleared and a person unlocks it at the
pendant, never within a few seconds of the stop (the station's safety function,
`hrc_drake.cell.station.safety_function`). In a live run (`hrc-drake simulate --live`) that person
is at the browser: `UnlockButton` puts "Unlock protective stop" in Meshcat's control panel and
drives the station's `safety.unlock` input, 1 for one period after each click, 0 otherwise. A
connected `safety.unlock` is a person's: the station's simulated operator no longer unlocks, so
a live run stays stopped until the click.

With its `safety.mode` input connected (the station's), the button is in the panel only while
the robot is in a protective stop, and the terminal says when it comes, what to do, and whether
a click took: a button that means something whenever it is there, and no click left over from
earlier (a click outside a stop would unlock nothing anyway). Unconnected, the button is always
there.

Clicks are counted with `Meshcat.GetButtonClicks` at every periodic update (the run's period, the
safety function's own, at the same instants: the function reads the pulse one period after the
click is seen, exactly once). Clicks that come faster than the pulses are passed on one at a
time, 0 between two pulses, so that each click is its own pulse. Tests press the button with
no browser as Drake's do, `meshcat._InjectWebsocketMessage(umsgpack.packb({"type": "button",
"name": UNLOCK_LABEL}))`; `tests/test_browser.py` clicks it in Chromium.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, replace

from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from hrc_drake.cell.ports import SafetyMode
from hrc_drake.hri.controls import add_button, control_name

UNLOCK_LABEL = control_name("Unlock protective stop")
_WHERE = '"Open Controls", top right of the Meshcat page'


@dataclass(frozen=True)
class PendantState:
    """What the button keeps between updates.

    Attributes:
        shown: the button is in the panel.
        seen: its click count when last read (counted from when it was shown).
        pending: clicks seen but not yet passed on as a pulse.
        stopped: the robot was in a protective stop at the last update.
        since: when that stop was first seen (None: not in one).
        wait_said: the terminal has said that the stop's unlock wait is over.
        pulses: pulses given so far (one per click).
        check_at: the time to look whether the last pulse unlocked (None: nothing to look at).
    """

    shown: bool = False
    seen: int = 0
    pending: int = 0
    stopped: bool = False
    since: float | None = None
    wait_said: bool = False
    pulses: int = 0
    check_at: float | None = None


class UnlockButton(LeafSystem):
    """The unlock button (see the module docstring).

    Input port: `safety.mode` (1, the `SafetyMode` code; optional). Output port:
    `safety.unlock` (1: unlock, for one period after each click). Updated every `period`.

    Args:
        meshcat: the live run's Meshcat.
        period: the update period [s] (the run's period, the safety function's).
        unlock_wait: seconds after a stop before an unlock takes (said in the terminal).
        say: where the words for the person go (default: stderr, as the live panel's).
    """

    def __init__(
        self,
        meshcat: Meshcat,
        period: float,
        unlock_wait: float,
        say: Callable[[str], None] | None = None,
    ):
        super().__init__()
        self.set_name("unlock_button")
        self.meshcat, self.period, self.unlock_wait = meshcat, period, unlock_wait
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self._mode = self.DeclareVectorInputPort("safety.mode", 1)
        self._pulse = self.DeclareDiscreteState(1)
        self._state = self.DeclareAbstractState(AbstractValue.Make(PendantState()))
        self.DeclareStateOutputPort("safety.unlock", self._pulse)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def connect(self, builder: DiagramBuilder, station) -> None:
        """Add this button to `builder` and wire it to `station` (a system in it): its pulse
        into the station's `safety.unlock`, the station's `safety.mode` in."""
        builder.AddSystem(self)
        builder.Connect(self.GetOutputPort("safety.unlock"), station.GetInputPort("safety.unlock"))
        if station.HasOutputPort("safety.mode"):
            builder.Connect(station.GetOutputPort("safety.mode"), self._mode)

    def state(self, context) -> PendantState:
        """The button's state in this system's `context`."""
        return context.get_abstract_state(self._state).get_value()

    def close(self) -> None:
        """Take the button out of the panel (a run that ends leaves none there)."""
        self.meshcat.DeleteButton(UNLOCK_LABEL, strict=False)

    def _update(self, context, state) -> None:
        now, old = context.get_time(), self.state(context)
        mode = None
        if self._mode.HasValue(context):
            mode = SafetyMode(round(self._mode.Eval(context)[0]))
        stopped = mode == SafetyMode.PROTECTIVE_STOP
        new = self._words(replace(old, stopped=stopped), old, now)
        new = self._panel(new, wanted=mode is None or stopped)
        pulse = 0.0
        # 0 after a pulse: clicks that come faster than the pulses stay distinct pulses.
        if new.pending > 0 and context.get_discrete_state(self._pulse).GetAtIndex(0) < 0.5:
            pulse = 1.0
            # The function reads the pulse at the next update; it has acted by the one after.
            new = replace(
                new, pending=new.pending - 1, pulses=new.pulses + 1, check_at=now + 2 * self.period
            )
        state.get_mutable_discrete_state(self._pulse).SetAtIndex(0, pulse)
        state.get_mutable_abstract_state(self._state).set_value(new)

    def _panel(self, new: PendantState, wanted: bool) -> PendantState:
        """The button up or down as `wanted`, and the clicks since the last look."""
        if not wanted:
            if new.shown:
                self.close()
            return replace(new, shown=False, seen=0, pending=0)
        if not new.shown:
            add_button(self.meshcat, UNLOCK_LABEL)
            # Counted from here: AddButton of a name still registered only resets its count.
            return replace(new, shown=True, seen=self.meshcat.GetButtonClicks(UNLOCK_LABEL))
        try:
            clicks = self.meshcat.GetButtonClicks(UNLOCK_LABEL)
        except RuntimeError:  # deleted by another hand: up again, counted from there
            add_button(self.meshcat, UNLOCK_LABEL)
            clicks, new = 0, replace(new, seen=0)
        before = new.seen if clicks >= new.seen else 0  # a count reset by another hand
        return replace(new, seen=clicks, pending=new.pending + clicks - before)

    def _words(self, new: PendantState, old: PendantState, now: float) -> PendantState:
        """What the terminal says: the stop, its unlock, a click that did not take."""
        if new.stopped and not old.stopped:
            self.say(
                f"protective stop at {now:.2f} s: the robot holds; once its cause has cleared "
                f"(and not within {self.unlock_wait:g} s of the stop) click "
                f'"{UNLOCK_LABEL}" under {_WHERE}'
            )
            new = replace(new, since=now, wait_said=False)
        elif old.stopped and not new.stopped:
            self.say(f"protective stop unlocked at {now:.2f} s: the robot goes on")
            return replace(new, since=None, check_at=None)
        if new.stopped and not new.wait_said and now >= new.since + self.unlock_wait - 1e-9:
            self.say(
                f"protective stop: {self.unlock_wait:g} s have passed; click "
                f'"{UNLOCK_LABEL}" once its cause has cleared'
            )
            new = replace(new, wait_said=True)
        if new.check_at is not None and now >= new.check_at - 1e-9:
            if new.stopped:
                self.say(
                    "still in the protective stop: an unlock takes once the cause has cleared "
                    f"and {self.unlock_wait:g} s after the stop; click again then"
                )
            return replace(new, check_at=None)
        return new


__all__ = ["UNLOCK_LABEL", "PendantState", "UnlockButton"]
