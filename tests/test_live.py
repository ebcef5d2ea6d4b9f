"""A person as the operator in the browser, driven with no browser: button messages are injected
into Meshcat the way Drake's own tests press buttons (the same code path as a click)."""

import base64
import re

import pytest

from hrc_drake.cell.run import run_scenario
from hrc_drake.cell.scenario import LEAN, load_cell_scenario

umsgpack = pytest.importorskip("umsgpack")

pytestmark = pytest.mark.slow


def test_a_live_run_follows_the_clicks_to_a_terminal_state(tmp_path):
    """Row 4 clicked by hand: F3 instead of the proposed F1 at step 1, then the robot's
    proposals; the run ends on the minimum-effort column, and the recording shows the
    choices."""
    row = load_cell_scenario("row4-forces-4", LEAN)
    clicks = {1: "F3"}
    prompts = []

    def click(prompt):
        prompts.append(prompt)
        name = prompt.button_for(clicks.get(prompt.step, prompt.proposal))
        message = umsgpack.packb({"type": "button", "name": name})
        prompt.meshcat._InjectWebsocketMessage(message)

    result = run_scenario(row, live=True, on_prompt=click, record=tmp_path / "live.html")
    assert result.error is None and result.done
    assert result.names == list(row.minimum_effort)
    assert [t.indicated for t in result.tasks] == ["F3", "S12", "F01"]
    assert [t.observed for t in result.tasks] == ["F3", "S12", "F01"]
    # The panel offered the proposal, the other feasible tasks, and the spec's mistake.
    first = prompts[0]
    assert first.proposal == "F1" and first.buttons[first.button_for("F1")] == "F1"
    assert {"F1", "F2", "F3", "S12", "S23"} <= set(first.buttons.values())
    assert any(name.startswith("mistake") for name in prompts[2].buttons)
    # Choices are drawn into the recording (the panel is not part of it).
    commands = _recorded_commands((tmp_path / "live.html").read_text())
    for path in (b"operator_choices/step_1", b"operator_choices/ghost", b"safety/stopped"):
        assert path in commands, path


def _recorded_commands(html: str) -> bytes:
    """The Meshcat commands a static page replays (base64 msgpack blobs), concatenated."""
    blobs = re.findall(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)", html)
    return b"".join(base64.b64decode(blob) for blob in blobs)
