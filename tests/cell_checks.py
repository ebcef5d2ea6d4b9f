"""What every lean run of a catalogue scenario must show (tests/test_catalogue.py, and the rows of
Table 2 in tests/test_closed_loop.py, which check more of their own)."""

import json

import pytest

from hrc_drake.scenario.load import load_scenario


def check_catalogue_run(name: str, result) -> None:
    """Terminal, no collision, separation kept by the controller's monitor and by the run's own
    check with never a touch, and the minimum-effort states where the file states them."""
    assert result.error is None, result.error
    assert result.done and result.final_kind == "terminal"
    assert result.collisions == []
    if result.safety is not None:
        assert result.safety.violations == 0 and result.safety.body_contacts == 0
        # The run's own check, the same for every mode (`hrc_drake.cell.run.safety_check`):
        # inside S_p only at a speed ISO/TS 15066 permits toward that body region.
        assert result.safety_check.passed and result.safety_check.body_contacts == 0
        # `simulate --json`'s `safety`: the check's, the function's and the monitor's apart.
        data = json.loads(json.dumps(result.to_json()))["safety"]
        check = data["check"]
        assert check["steps_inside_sp"] == result.safety_check.violations
        assert check["passed"] and check["steps_beyond_permissible_speed"] == 0
        assert check["body_contacts"] == 0 and check["contacts"] == []
        assert data["summary"] == result.safety_check.summary()
        assert data["monitor"]["violations"] == result.safety.violations
        assert check["checked_steps"] == pytest.approx(result.sim_time / 0.02, abs=2)
    expected = load_scenario(name).minimum_effort
    if expected:
        assert result.names == list(expected)
