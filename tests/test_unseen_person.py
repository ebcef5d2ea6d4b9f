"""A person the forecast has not seen (`body.behaviour: unseen`): the simulated desk operator
departs from the activity model the controller forecasts with (other timing, hesitations,
changes of mind, a second fetch), deterministically per operator seed, with a human hand; the
forecast keeps modelling the ordinary person."""

import numpy as np
import pytest

from hrc_drake.cell.controller.forecast import Anchor, OperatorForecast
from hrc_drake.cell.ports import OperatorActivity
from hrc_drake.cell.station.desk import desk_script
from hrc_drake.hri.activity import Desk, DeskBin, HandTimeline, Person, indication_timeline
from hrc_drake.hri.unseen import HUMAN_ACCELERATION, HUMAN_SPEED
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import BodyConfig, ScenarioError

# The desk of `shared-desk` (bins and the flange case's seats, as `desk_of` makes them).
DESK = Desk(
    bins=(
        DeskBin("bolts", "bolts", (0.41, -0.18, 0.05)),
        DeskBin("nuts", "nuts", (0.45, -0.03, 0.05)),
    ),
    seats={
        "F1": (0.30, -0.08, 0.0155),
        "F3": (0.30, 0.08, 0.0155),
        "S23": (0.30, 0.04, 0.0155),
        "F03": (0.30, 0.08, 0.0355),
    },
    parts={"F1": "F", "F3": "F", "S23": "S", "F03": "F"},
    bolts={"F": 4, "S": 4},
)
TASKS = ("F1", "S23", "F03")
BODY = BodyConfig(activity="desk", behaviour="unseen", handful=2, spread=0.2)
SEEDS = range(6)


def _timeline(seed: int, step: int, task: str, body: BodyConfig = BODY) -> HandTimeline:
    """The simulated operator's hand after indicating `task` at decision `step`, at t = 2 s."""
    indicated = OperatorActivity(answered_step=step, answered_at=2.0, answered_task=task)
    return desk_script(body, seed, DESK).timeline(indicated)


def _places(timeline: HandTimeline) -> list[np.ndarray]:
    """Where the activity's hand stays: rest, the bins, the pointing spots."""
    points = [DESK.point(t) for t in DESK.seats]
    return [timeline.rest, *(np.asarray(b.grab) for b in DESK.bins), *points]


def _at_a_place(p, places, tol: float = 1e-6) -> bool:
    return min(np.linalg.norm(p - q) for q in places) < tol


def _hesitations(timeline: HandTimeline) -> list[float]:
    """When the hand stands still mid-reach (not at a place of the activity) between a move
    toward a goal and a move on toward the same goal."""
    out, moves, places = [], timeline.moves, _places(timeline)
    for before, pause, after in zip(moves, moves[1:], moves[2:], strict=False):
        still = pause.end - pause.start > 0.2 and np.allclose(pause.a, pause.b)
        if not still or _at_a_place(pause.a, places):
            continue
        mid = (pause.start + pause.end) / 2
        assert np.linalg.norm(timeline.velocity(mid)) < 1e-9
        came, goes = pause.a - before.a, after.b - pause.a
        cos = came.dot(goes) / (np.linalg.norm(came) * np.linalg.norm(goes))
        if cos > 0.999 and _at_a_place(after.b, places):
            out.append(mid)
    return out


def _changes_of_mind(timeline: HandTimeline) -> list[float]:
    """When a reach that ends at a place of the activity set off toward another place."""
    out, places = [], _places(timeline)
    for move in timeline.moves:
        if move.end - move.start < 0.05 or not _at_a_place(move.b, places):
            continue
        early = timeline.velocity(move.start + 0.1 * (move.end - move.start))
        if np.linalg.norm(early) < 1e-6:
            continue
        heading = early / np.linalg.norm(early)

        def toward(p, start=move.a, heading=heading):
            d = p - start
            return np.linalg.norm(d) > 0.05 and heading.dot(d / np.linalg.norm(d)) > 0.999

        others = [p for p in places if np.linalg.norm(p - move.b) > 0.08]
        if not toward(move.b) and any(toward(p) for p in others):
            out.append(move.start)
    return out


def _samples(timeline: HandTimeline, dt: float = 0.002):
    times = np.arange(timeline.moves[0].start, timeline.end + dt, dt)
    return times, np.array([timeline.at(t) for t in times])


def test_modelled_is_the_default_and_the_activity_model_itself():
    assert BodyConfig().behaviour == "modelled"
    modelled = BodyConfig(activity="desk", handful=2, spread=0.2)
    for seed in SEEDS:
        person = modelled.person(seed=seed)
        for task in TASKS:
            ours = _timeline(seed, 1, task, modelled)
            model = indication_timeline(person, DESK, task, 2.0)
            assert len(ours.moves) == len(model.moves)
            for a, b in zip(ours.moves, model.moves, strict=True):
                assert (a.start, a.end, a.what) == (b.start, b.end, b.what)
                assert np.array_equal(a.a, b.a) and np.array_equal(a.b, b.b)


def test_the_unseen_person_leaves_every_forecast_timeline_of_the_same_seed():
    """The forecast the controller keeps (the scenario's person, its full timing spread after
    the indication) misses the unseen hand by more than `safety.departure` (0.15 m), while the
    modelled person of the same seed stays within its spread."""
    forecast = OperatorForecast(BODY.person(), DESK, delay=2.0, sigma=0.3)
    offsets = forecast.offsets(True)
    modelled = BodyConfig(activity="desk", handful=2)  # spread 0: the forecast's own person
    for seed in SEEDS:
        for step, task in enumerate(TASKS, 1):
            anchor = Anchor(task, 2.0)
            times = np.arange(2.0, 18.0, 0.05)
            unseen = _timeline(seed, step, task)
            gaps = [forecast.departure(anchor, unseen.at(t), t, offsets) for t in times]
            assert max(gaps) > 0.15, (seed, task)
            same = _timeline(seed, step, task, modelled)
            assert max(forecast.departure(anchor, same.at(t), t) for t in times) < 1e-9
            # It is busy for other lengths of time than the model says.
            assert unseen.end != pytest.approx(forecast.timeline(anchor).end, abs=0.05)


def test_the_unseen_person_hesitates_and_changes_their_mind_mid_reach():
    hesitations = changes = refetches = 0
    for seed in SEEDS:
        for step, task in enumerate(TASKS, 1):
            timeline = _timeline(seed, step, task)
            hesitations += len(_hesitations(timeline))
            changes += len(_changes_of_mind(timeline))
            stays = [m for m in timeline.moves if m.what == "fetch" and np.allclose(m.a, m.b)]
            refetches += len(stays) > len(DESK.bins)
    assert hesitations >= 5 and changes >= 5 and refetches >= 3
    # The modelled person does neither.
    modelled = BodyConfig(activity="desk", handful=2, spread=0.2)
    for seed in SEEDS:
        timeline = _timeline(seed, 1, "F1", modelled)
        assert not _hesitations(timeline) and not _changes_of_mind(timeline)


def test_the_same_seed_is_the_same_person_and_another_seed_another():
    for step, task in enumerate(TASKS, 1):
        times, one = _samples(_timeline(3, step, task))
        _, again = _samples(_timeline(3, step, task))
        assert np.array_equal(one, again)
        another = _timeline(4, step, task)
        other = np.array([another.at(t) for t in times])
        assert np.abs(other - one).max() > 0.05
    # Each indication of one person is drawn anew.
    first, second = _timeline(3, 1, "F1"), _timeline(3, 2, "F1")
    assert first.end != second.end


def test_the_unseen_hand_is_human_and_within_reach():
    """Peak speed at most 1.6 m/s, acceleration at most `HUMAN_ACCELERATION` (the modelled
    hands' bolting reaches in lean runs go to 24-29 m/s²), and every point reachable."""
    dt = 0.002
    for seed in SEEDS:
        person: Person = BODY.person(seed=seed)
        for step, task in enumerate(TASKS, 1):
            timeline = _timeline(seed, step, task)
            times, hand = _samples(timeline, dt)
            velocity = np.array([timeline.velocity(t) for t in times])
            # The velocity is the position's derivative (the superposed turns included).
            assert np.allclose(np.gradient(hand, dt, axis=0)[1:-1], velocity[1:-1], atol=2e-3)
            assert np.linalg.norm(velocity, axis=1).max() <= HUMAN_SPEED + 1e-6
            acceleration = np.gradient(velocity, dt, axis=0)
            assert np.linalg.norm(acceleration, axis=1).max() <= HUMAN_ACCELERATION + 0.2
            assert all(person.reaches(p) for p in hand[::10])
            assert np.allclose(timeline.at(timeline.end + 1.0), person.rest_hand)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (
            "{body: {behaviour: sometimes}}",
            "body.behaviour: unknown behaviour 'sometimes'; use modelled or unseen",
        ),
        ("{body: {activity: bolting, behaviour: unseen}}", "set body.activity: desk too"),
    ],
)
def test_bad_behaviours_are_one_line_errors_naming_the_key(text, needle):
    with pytest.raises(ScenarioError) as err:
        load_scenario("shared-desk", text)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_the_controllers_forecast_does_not_know_the_unseen_person():
    """The same forecast for a modelled and an unseen operator: it models the ordinary
    person whatever the station's body does."""
    from hrc_drake.cell.controller.build import keep_clear_settings
    from hrc_drake.cell.robot_envelope import RobotEnvelope
    from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
    from hrc_drake.tasks.spec import load_spec

    forecasts = []
    for behaviour in ("modelled", "unseen"):
        scenario = load_cell_scenario("shared-desk", [f"{{body: {{behaviour: {behaviour}}}}}"])
        design = cell_design(scenario, load_spec(scenario.assembly_path))
        settings = keep_clear_settings(
            scenario, design, RobotEnvelope(design), motion_options(scenario)
        )
        forecasts.append(settings.forecast)
    modelled, unseen = forecasts
    assert unseen.person == modelled.person and unseen.desk == modelled.desk
    anchor = Anchor("F1", 2.0)
    for a, b in zip(unseen.timeline(anchor).moves, modelled.timeline(anchor).moves, strict=True):
        assert (a.start, a.end) == (b.start, b.end) and np.array_equal(a.b, b.b)


@pytest.mark.slow
def test_shared_desk_with_an_unseen_person_ends_without_collision_or_contact():
    from hrc_drake.cell.run.run import run_scenario
    from hrc_drake.cell.scenario import LEAN, load_cell_scenario

    text = "{body: {behaviour: unseen}, operator: {seed: 1}}"
    result = run_scenario(load_cell_scenario("shared-desk", [text, LEAN]))
    assert result.done and result.to_json()["terminal"]
    assert not result.collisions
    assert result.safety.body_contacts == 0 and result.safety_check.body_contacts == 0
    # The person is not the forecast's: the controller re-timed its plans around what it saw.
    assert result.replans > 0
