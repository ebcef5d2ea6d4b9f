"""The robot moves on its prediction: it starts on the task it commits to while the operator's
indication is on its way, and turns when the indication names another task."""

import dataclasses

import numpy as np
import pytest

from hrc_drake.cell.controller.supervisor import Mode
from hrc_drake.cell.ports import PartStatus
from hrc_drake.cell.run.run import build_closed_loop
from hrc_drake.cell.scenario import LEAN, load_cell_scenario
from hrc_drake.robot_names import UR3


def _loop(scenario: str, *texts: str):
    return build_closed_loop(load_cell_scenario(scenario, [LEAN, *texts]))


def _arm_speeds(loop, until: float = 120.0) -> list[tuple[float, float]]:
    """(time, the arm's fastest joint speed) every 0.05 s of a run to its end."""
    plant, station = loop.station.plant, loop.station
    speeds, t = [], 0.0
    while loop.advance_to(t) not in (Mode.DONE, Mode.FAILED) and t < until:
        context = plant.GetMyContextFromRoot(loop.root_context)
        v = plant.GetVelocities(context, station.instances[UR3])
        speeds.append((t, float(np.abs(v).max())))
        t += 0.05
    return speeds


def test_the_robot_starts_on_its_commitment_before_the_indication():
    loop = _loop("row1-optimal")
    speeds = _arm_speeds(loop)
    result = loop.result()
    assert result.done and result.interaction == "anticipate"
    first = result.tasks[0]
    assert first.committed == "F1" and first.indicated == "F1"
    assert not first.retargeted and not first.swapped
    # The indication comes about 2 s after the prompt (the pointer's delay); the arm is moving
    # well before it.
    assert first.indicated_at > 1.0
    assert max(v for t, v in speeds if t < first.indicated_at) > 0.1
    # It holds the part for the bolts after the indication, standing still while it holds.
    assert first.indicated_at < first.held_at < first.end_time
    assert max(v for t, v in speeds if first.held_at <= t <= first.held_at + 0.4) < 0.05
    step = result.to_json()["steps"][0]
    assert step["committed"] == "F1" and step["indicated_at"] == round(first.indicated_at, 3)
    assert step["held_at"] == round(first.held_at, 3)


def test_in_wait_mode_the_robot_holds_still_until_the_indication():
    loop = _loop("row1-optimal", "{interaction: {mode: wait}}")
    speeds = _arm_speeds(loop)
    result = loop.result()
    assert result.done and result.interaction == "wait"
    first = result.tasks[0]
    assert first.committed is None and first.indicated_at > 1.0
    assert max(v for t, v in speeds if t < first.indicated_at) < 1e-3
    # Waiting costs the indication's delay at every boundary: the same row anticipating ends
    # sooner.
    assert result.sim_time > _loop("row1-optimal").run().sim_time + 3.0


def test_a_wrong_seat_is_retargeted_with_the_part_in_the_gripper():
    # Row 8: the robot starts on F1; the operator indicates F3 (the same kind of part, another
    # seat) while the flange is being lifted. The robot carries it on to F3 without letting go,
    # and without slowing down: it turns at the lift's end, where the plan's own motions meet.
    # (Without the operator's body: separation would slow the arm by the resting hand.)
    loop = _loop("row8-forces-4-then-8", "{body: {enabled: false}}")
    plant, station = loop.station.plant, loop.station
    held = []  # the flange's status from the indication to the place
    moving = []  # (the speed scale, the arm's fastest joint speed) over the same stretch
    t = 0.0
    while loop.advance_to(t) not in (Mode.DONE, Mode.FAILED) and t < 120:
        status = loop.status
        if status.step == 1 and status.question.indicated_at is not None and status.bolted is False:
            plan = status.plan
            # Up to 50 ms before the plan's in-place instant: the flange sits half a millimetre
            # lower in the fingers than planned (the pads sink into it, and the RG2's linkage
            # turns their closing into travel along the approach), so it may touch its seat's
            # floor a step or two early (measured: 11 ms).
            if plan is None or status.plan_time(t) < plan.t_in_place - 0.05:
                held.append(loop.cell.configuration(loop.root_context).status("oval_flange_1"))
                context = plant.GetMyContextFromRoot(loop.root_context)
                v = plant.GetVelocities(context, station.instances[UR3])
                moving.append((status.clock.speed, float(np.abs(v).max())))
        t += 0.02
    result = loop.result()
    assert result.done and [t.observed for t in result.tasks] == ["F3", "S12", "F01"]
    first = result.tasks[0]
    assert (first.committed, first.indicated, first.retargeted, first.swapped) == (
        "F1",
        "F3",
        True,
        False,
    )
    assert any("re-targets to F3 at the lift's end" in e for e in result.events)
    # From the indication to the place the flange stays in the gripper, the robot never slows
    # down, and the arm is still only for a moment where the lift ends and the carry starts.
    assert held and set(held) == {PartStatus.HELD}
    assert min(scale for scale, _ in moving) == 1.0
    assert _longest_run(speed < 0.05 for _, speed in moving) * 0.02 <= 0.1
    assert not result.collisions


def test_a_wrong_part_is_put_back_in_the_tray_and_the_indicated_one_fetched():
    # The robot commits to F1 (an oval flange); the operator indicates S12 (the square one).
    loop = _loop("row1-optimal", "{operator: {deviations: [{step: 1, task: S12}]}}")
    seen_back = False
    t = 0.0
    while loop.advance_to(t) not in (Mode.DONE, Mode.FAILED) and t < 120:
        status = loop.status
        fetching = status.plan is not None and status.plan.instance == "square_flange"
        if status.step == 1 and fetching and not seen_back:
            config = loop.cell.configuration(loop.root_context)
            seen_back = config.status("oval_flange_1") == PartStatus.TRAY
        t += 0.05
    result = loop.result()
    assert result.done, result.error
    first = result.tasks[0]
    assert (first.committed, first.indicated, first.observed) == ("F1", "S12", "S12")
    assert first.swapped and not first.retargeted and first.part == "square_flange"
    assert any("turns to S12 (return)" in e for e in result.events)
    assert seen_back  # the oval flange was read home in the tray before the square one went
    assert not result.collisions


def test_task_level_and_cell_timelines_agree_on_a_scripted_run():
    # Row 8 at full holds: the robot bets on F1, the operator indicates F3 (a re-target), then
    # follows. The task level plays the same run from a cost table of the edges and the bet the
    # run took, planned by the motion layer, with the same delay draws.
    from hrc_drake.cell.run.costs import bet_seconds, compute_cost_table, timing_planner
    from hrc_drake.cell.run.evaluate import task_level_run
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import motion_options
    from hrc_drake.tasks.costs import uniform_bets
    from hrc_drake.tasks.graph import generate_states
    from hrc_drake.tasks.spec import load_spec

    scenario = load_cell_scenario("row8-forces-4-then-8", ["{body: {enabled: false}}"])
    space = generate_states(load_spec(scenario.assembly_path))
    cell = run_scenario(scenario)
    assert cell.done and [t.retargeted for t in cell.tasks] == [True, False, False]
    planner = timing_planner(space, motion_options(scenario))
    edges = {(t.state, task) for t in cell.tasks for task in (t.observed, t.committed)}
    table = compute_cost_table(space, planner, edges=sorted(edges))
    bets = uniform_bets(space, retarget=0.0, swap=0.0)  # only the run's own bet is played
    first = cell.tasks[0]
    bets[(), first.committed, first.observed] = bet_seconds(
        planner, space, (), first.committed, first.observed
    )
    task = task_level_run(scenario, space, dataclasses.replace(table, bets=bets))
    assert task.completed and (task.commits, task.retargets, task.swaps) == (3, 1, 0)
    # The same delays (the cell's indication comes a few 20 ms periods later: the prompt, the
    # operator and the Supervisor each act on their next update), and the cell's time within 5 %
    # of the task level's (the cell adds the parts' settling and those periods).
    delays = [t.indicated_at - start for t, start in zip(cell.tasks, _prompts(cell), strict=True)]
    assert 0.0 < sum(delays) - task.indication_delay < 0.1 * len(delays)
    assert cell.sim_time == pytest.approx(task.seconds, rel=0.05)


def _longest_run(flags) -> int:
    """The length of the longest run of true values."""
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


def _prompts(result) -> list[float]:
    """When each task's prompt appeared: at the start, then as the task before ended."""
    return [0.0, *(t.end_time for t in result.tasks[:-1])]
