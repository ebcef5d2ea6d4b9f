"""Contact judged by ISO/TS 15066 Annex A (`hrc_drake.cell.contact_limits`), with the robot's
effective mass from the plant (`hrc_drake.cell.effective_mass`), in the run's own check and at
`simulate --strict`."""

import dataclasses
import json

import numpy as np
import pytest

from hrc_drake.cell.contact_limits import (
    CHEST,
    HAND,
    REGIONS,
    SKULL,
    clamped,
    judge,
    least_permissible_speeds,
)
from hrc_drake.cell.effective_mass import EffectiveMass
from hrc_drake.cell.person import BODY_GROUPS, BODY_RADII
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope, nearest_points
from hrc_drake.cell.run.safety_check import SafetySample, check_separation
from hrc_drake.cell.ssm import contact_speeds
from hrc_drake.cell_models import CellDesign
from hrc_drake.cli import main
from hrc_drake.scenario.safety import SafetyConfig
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.spec import load_spec

READY = np.array(Scenario().station.ur3.ready, dtype=float)
OPENING = 0.045  # m
RADIUS = 0.04  # m, a probe sphere's
FAR = np.array([10.0, 10.0, 10.0])  # where the parts of a body not under test stand


@pytest.fixture(scope="module")
def envelope():
    return RobotEnvelope(CellDesign.of(load_spec()))


def test_annex_a_speeds_and_forces():
    """The energy-transfer model's figures: the hand against a rigid robot 280 N / √(0.6 kg ·
    75 N/mm) = 1.32 m/s, against 4.7 kg (a UR3 and gripper by the standard's M/2) ≈ 1.4 m/s;
    clamped, half; the force at the permissible speed is the permissible force; none at the
    head."""
    rigid, _, limit = judge(HAND, False, 0.0, np.inf)
    assert rigid == pytest.approx(280.0 / np.sqrt(0.6 * 75e3)) and limit == 280.0
    ur3, force, _ = judge(HAND, False, 1.0, 4.7)
    assert ur3 == pytest.approx(1.40, abs=0.01) and force == pytest.approx(280.0 / ur3)
    assert judge(HAND, True, 0.0, 4.7)[0] == pytest.approx(ur3 / 2)
    assert judge(CHEST, False, 0.0, np.inf)[0] == pytest.approx(0.28)
    assert judge(SKULL, False, 0.1, 4.7)[0] == 0.0 and judge(SKULL, False, 0.1, 4.7)[2] == 0.0


def _body(centres: np.ndarray) -> BodySpheres:
    return BodySpheres(centres, BODY_RADII, np.zeros_like(centres), BODY_GROUPS)


def test_the_speed_inside_s_p_is_the_region_s_at_any_mass():
    """At run time the arm may approach a region inside S_p no faster than the contact speed
    and than the region permits against a robot of any mass: the default 0.25 m/s binds every
    region but the head; a contact speed of 1 m/s is held to 0.28 m/s at the chest."""
    body = _body(np.zeros((len(BODY_RADII), 3)))
    least = least_permissible_speeds(body)
    by_part = [float(least[start]) for start, _ in BODY_GROUPS]
    assert by_part == pytest.approx([1.32, 1.13, 1.0, 0.28, 0.0], abs=0.01)
    assert [r.name for r in REGIONS][3:] == ["chest", "skull and forehead"]
    default = contact_speeds(0.25, body)
    assert set(default[: BODY_GROUPS[-1][0]]) == {0.25} and default[-1] == 0.0
    fast = contact_speeds(1.0, body)
    assert fast[BODY_GROUPS[3][0]] == pytest.approx(0.28, abs=0.01)
    assert fast[0] == 1.0


def test_a_region_is_clamped_only_over_the_table_pushed_down():
    body = BodySpheres(
        np.array([[0.3, 0.0, 0.05], [0.3, 0.0, 0.40], [0.9, 0.0, 0.05]]),
        np.full(3, RADIUS),
        np.zeros((3, 3)),
    )
    down, sideways = np.array([[0.0, 0.0, -1.0]] * 3), np.array([[1.0, 0.0, 0.0]] * 3)
    assert clamped(body, np.arange(3), down).tolist() == [True, False, False]
    assert not clamped(body, np.arange(3), sideways).any()


def test_effective_mass_from_the_plant(envelope):
    """Never below the standard's M/2 (+ the part); where the arm's inertia exceeds it, the
    plant's own figure, the same along u and −u and larger with the part held; infinite on
    the fixed base."""
    masses = EffectiveMass(envelope)
    assert 4.0 < masses.floor(None) < 6.0  # the UR3's links and the RG2: about 9.4 kg moving
    assert masses.floor("square_flange") > masses.floor(None)
    shapes = envelope.shapes(None, True)
    R_WB, p_WB = envelope.pose(READY, OPENING)
    centres = p_WB[shapes.body] + np.einsum("mij,mj->mi", R_WB[shapes.body], shapes.p_BC)
    rows = np.arange(len(shapes.names))
    up = np.tile([0.0, 0.0, 1.0], (len(rows), 1))
    along = masses.along(READY, OPENING, None, shapes, rows, centres, up)
    assert np.all(along >= masses.floor(None))
    base = shapes.link == len(envelope.links)
    assert np.all(np.isinf(along[base])) and not np.isinf(along[~base]).all()
    heavy = np.flatnonzero(np.isfinite(along) & (along > 2 * masses.floor(None)))
    assert len(heavy) > 0  # the upper arm lifted at the shoulder: its own inertia, not M/2
    back = masses.along(READY, OPENING, None, shapes, rows, centres, -up)
    assert back[heavy] == pytest.approx(along[heavy])
    held = masses.along(READY, OPENING, "square_flange", shapes, rows, centres, up)
    assert np.all(held[heavy] > along[heavy])


def _trace(v, bodies) -> list[SafetySample]:
    v = np.asarray(v, dtype=float)
    return [
        SafetySample(
            time=0.02 * k,
            q=READY,
            v=v,
            commanded=v,
            opening=OPENING,
            carrying=None,
            body=body,
        )
        for k, body in enumerate(bodies)
    ]


def _one_part(part: int, centre: np.ndarray) -> BodySpheres:
    """A body of the five parts, one sphere each, with `part` at `centre`, the others far."""
    centres = FAR + np.arange(5)[:, None]
    centres[part] = centre
    groups = tuple((k, k + 1) for k in range(5))
    return BodySpheres(centres, np.full(5, RADIUS), np.zeros((5, 3)), groups)


def test_the_same_approach_is_permitted_toward_the_hand_not_the_chest(envelope):
    """The shoulder lifts the wrist toward a still probe 8 cm beyond its nearest shape at about
    1.2 m/s (a test's speed, faster than a UR3's shoulder): the hand permits it (≈1.4 m/s
    against the arm's effective mass), the chest (≈0.86 m/s) and the head do not."""
    shapes = envelope.shapes(None, True)
    R_WB, p_WB = envelope.pose(READY, OPENING)
    above = p_WB[-1] + np.array([0.0, 0.0, 0.5])
    pairs = nearest_points(shapes, R_WB, p_WB, above[None, :])
    k = int(np.argmin(pairs.distance[:, 0]))
    probe = above - pairs.direction[k, 0] * (pairs.distance[k, 0] - 0.08)
    lift = [0.0, -4.0, 0.0, 0.0, 0.0, 0.0]
    judged = {}
    for part, region in enumerate(("hand", "lower arm", "upper arm", "chest", "head")):
        trace = _trace(lift, [_one_part(part, probe)] * 10)
        judged[region] = check_separation(trace, envelope, SafetyConfig(), 5.0)
    hand, chest = judged["hand"], judged["chest"]
    assert hand.violations == 10 and hand.passed and hand.worst.region == "hand"
    assert 0.86 < hand.worst.speed < hand.worst.permissible_speed
    assert hand.worst.robot_mass >= EffectiveMass(envelope).floor(None)
    assert chest.beyond_permissible == 10 and not chest.passed
    assert chest.worst.permissible_speed < chest.worst.speed == pytest.approx(hand.worst.speed)
    assert chest.worst.force > chest.worst.force_limit == 280.0
    assert judged["lower arm"].passed and judged["upper arm"].passed
    assert not judged["head"].passed
    assert "FASTER than ISO/TS 15066 permits" in chest.summary()


def test_a_hand_pinned_on_the_table_is_judged_by_its_quasi_static_force(envelope):
    """A hand on the table under the fingers, the arm pushing down: a contact at every step,
    judged quasi-static (140 N: half the transient speed). At about 0.6 m/s it is within; at
    0.9 m/s beyond it, though a transient contact with the hand would permit that speed."""
    wrist = envelope.pose(READY, OPENING)[1][-1]
    hand = BodySpheres(
        np.array([[wrist[0], wrist[1], RADIUS]]), np.array([RADIUS]), np.zeros((1, 3))
    )
    slow = check_separation(_trace([0, 2.0, 0, 0, 0, 0], [hand] * 10), envelope, SafetyConfig(), 5)
    fast = check_separation(_trace([0, 3.0, 0, 0, 0, 0], [hand] * 10), envelope, SafetyConfig(), 5)
    assert slow.body_contacts == fast.body_contacts == 10
    assert slow.passed and slow.contacts_beyond == 0
    touch = fast.contacts[0]
    assert touch.clamped and touch.force_limit == 140.0 and touch.region == "hand"
    assert touch.permissible_speed < touch.speed < judge(HAND, False, 0.0, touch.robot_mass)[0]
    reduced = 1.0 / (1.0 / HAND.mass + 1.0 / touch.robot_mass)
    assert touch.force == pytest.approx(touch.speed * np.sqrt(reduced * HAND.stiffness))
    assert fast.contacts_beyond == 10 and not fast.passed
    data = fast.to_json()
    assert data["contacts_beyond_limits"] == 10 and data["contacts"][0]["clamped"] is True
    assert "BEYOND the permissible force" in fast.summary()


@pytest.mark.slow
def test_strict_exits_nonzero_when_the_check_fails(capsys, monkeypatch):
    """`simulate --strict` exits 3, naming the failure, when the run's check does not pass;
    without `--strict`, or with the check passed, the run's own status (0)."""
    import hrc_drake.cli.simulate as simulate

    real = simulate._run
    results = {}

    def run(*args, **kwargs):
        result = real(*args, **kwargs)
        results["passed"] = result.safety_check.passed
        if results.get("break"):
            check = dataclasses.replace(
                result.safety_check, violations=2, beyond_permissible=2, regions=(("chest", 2),)
            )
            result = dataclasses.replace(result, safety_check=check)
        return result

    monkeypatch.setattr(simulate, "_run", run)
    common = ["simulate", "--scenario", "row1-optimal", "--lean", "--json"]
    assert main([*common, "--strict"]) == 0 and results["passed"]
    summary = json.loads(capsys.readouterr().out)["safety"]["summary"]
    assert summary.startswith("kept S_p") or "every approach" in summary
    results["break"] = True
    assert main([*common, "--strict"]) == 3
    err = capsys.readouterr().err
    assert "--strict: the run's safety check failed" in err and "FASTER" in err
    assert main(common) == 0
