"""The separation pipeline (`hrc_drake.cell.separation_pipeline`): the envelope's own pairs, kept
by the values they were computed from; the planned limit that judges only the pairs that can
limit the plan gives what judging every pair gives; the forecast monitor decides as the
controller's monitor would, through the controller's one pipeline."""

import numpy as np
import pytest

from hrc_drake.cell.contact_limits import touchable
from hrc_drake.cell.controller.build import keep_clear_settings
from hrc_drake.cell.controller.intent import MotionIntent
from hrc_drake.cell.controller.separation import (
    BAND_CREEP,
    CONTACT_SHARE,
    CREEP_SHARE,
    SLOWEST_SCALE,
    assess,
    planned_limit,
    planned_scales,
)
from hrc_drake.cell.person import BODY_GROUPS, BODY_RADII, CHAIN_GAP
from hrc_drake.cell.ports import BodySpheres
from hrc_drake.cell.robot_envelope import RobotEnvelope, nearest_points
from hrc_drake.cell.scenario import cell_design, load_cell_scenario, motion_options
from hrc_drake.cell.separation_pipeline import SeparationPipeline, pipeline_of
from hrc_drake.cell.ssm import entry_scales, separation_constant, stopping_time
from hrc_drake.cell_models import CellDesign
from hrc_drake.scenario.safety import SafetyConfig
from hrc_drake.scenario.schema import Scenario
from hrc_drake.tasks.spec import load_spec

READY = np.array(Scenario().station.ur3.ready, dtype=float)
ACCELERATION = 5.0  # rad/s^2


@pytest.fixture(scope="module")
def envelope():
    return RobotEnvelope(CellDesign.of(load_spec()))


def _body(rng, spread: float = 0.5, far: float = 0.0) -> BodySpheres:
    """A whole body's spheres scattered within `spread` of a point `far` m before the arm,
    moving."""
    n = len(BODY_RADII)
    centres = np.array([0.3 + far, 0.0, 0.2]) + rng.uniform(-spread, spread, (n, 3))
    return BodySpheres(centres, np.array(BODY_RADII), rng.normal(0.0, 0.5, (n, 3)), BODY_GROUPS)


def test_the_pipeline_gives_the_envelope_s_own_pairs(envelope):
    pipeline = SeparationPipeline(envelope)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = READY + rng.uniform(-0.5, 0.5, 6)
        body = _body(rng)
        geometry = pipeline.pairs(q, 0.045, "square_flange", body)
        R_WB, p_WB = envelope.pose(q, 0.045)
        pairs = nearest_points(envelope.shapes("square_flange", True), R_WB, p_WB, body.centres)
        for name in ("distance", "witness", "direction"):
            assert np.array_equal(getattr(geometry.pairs, name), getattr(pairs, name)), name
        radii = body.radii[None, :] * (1.0 + CHAIN_GAP)
        assert np.array_equal(geometry.gap, pairs.distance - radii)


def test_a_question_asked_again_is_answered_from_memory(envelope):
    pipeline = pipeline_of(envelope)
    assert pipeline_of(envelope) is pipeline and pipeline_of(pipeline) is pipeline
    body = _body(np.random.default_rng(1))
    first = pipeline.pairs(READY, None, None, body)
    assert pipeline.pairs(READY.copy(), None, None, body) is first
    assert pipeline.robot(READY, None, None) is first.robot
    # Another reading (even of the same values), pose, opening or part: computed anew.
    again = BodySpheres(body.centres, body.radii, body.velocities, body.groups)
    assert pipeline.pairs(READY, None, None, again) is not first
    assert pipeline.robot(READY + 0.01, None, None) is not first.robot
    assert pipeline.robot(READY, 0.045, None) is not first.robot
    assert pipeline.robot(READY, None, "square_flange") is not first.robot


def _every_pair(geometry, v_r1, t_s1, config, sampling, lag, creep) -> float:
    """The plan's limit judged over every pair (the arithmetic before the pipeline judged only
    the pairs that can limit)."""
    gap, v_h, t_r = geometry.gap, geometry.person_speed(), config.reaction_time
    t_rp = t_r + sampling
    separated = planned_scales(v_h, gap, v_r1, t_rp, t_s1, config, gap - config.slow_band)
    if creep and separated.min() < BAND_CREEP:
        within = planned_scales(v_h, gap, v_r1, t_rp, t_s1, config, gap)
        separated = np.maximum(separated, np.minimum(CREEP_SHARE * within, BAND_CREEP))
    slow = CONTACT_SHARE * config.contact_speed / np.maximum(v_r1, 1e-9)
    reaction = t_r + sampling + lag
    short_of = entry_scales(gap, separation_constant(config), v_r1 * reaction, v_r1 * t_s1 / 2)
    slow = np.where(touchable(geometry.body)[None, :], np.minimum(slow, short_of), 0.0)
    limit = float(np.maximum(separated, np.minimum(slow, 1.0)).min())
    return 0.0 if limit < SLOWEST_SCALE else limit


@pytest.mark.parametrize("contact_speed", [0.0, 0.25])
def test_the_planned_limit_judges_only_the_pairs_that_can_limit(envelope, contact_speed):
    pipeline = SeparationPipeline(envelope)
    config = SafetyConfig(contact_speed=contact_speed)
    rng = np.random.default_rng(2)
    limits = []
    for k in range(60):
        q = READY + rng.uniform(-0.4, 0.4, 6)
        qdot = rng.uniform(-1.0, 1.0, 6)
        geometry = pipeline.pairs(q, 0.045, None, _body(rng, 0.3, far=0.05 * k))
        v_r1 = np.maximum(0.0, geometry.robot_speeds(qdot[None, :])[0])
        t_s1 = stopping_time(np.abs(qdot), ACCELERATION)
        for creep in (False, True):
            mine = planned_limit(geometry, v_r1, t_s1, config, 0.02, 0.04, creep)
            assert mine == _every_pair(geometry, v_r1, t_s1, config, 0.02, 0.04, creep)
            limits.append(mine)
    # The bodies span a stop, slowing and full speed.
    assert min(limits) == 0.0 and max(limits) == 1.0
    assert any(0.0 < x < 1.0 for x in limits)


def test_the_forecast_monitor_decides_as_the_monitor_through_the_controller_s_pipeline():
    scenario = load_cell_scenario("shared-desk")
    design = cell_design(scenario, load_spec(scenario.assembly_path))
    pipeline = SeparationPipeline(RobotEnvelope(design))
    options = motion_options(scenario)
    settings = keep_clear_settings(scenario, design, pipeline, options)
    rng = np.random.default_rng(3)
    period, safety = scenario.run.period, scenario.safety
    seen = []
    for k in range(20):
        q = READY + rng.uniform(-0.4, 0.4, 6)
        qdot = rng.uniform(-1.0, 1.0, 6)
        body = _body(rng, 0.3, far=0.15 * k)
        args = (q, qdot, 0.045, None, body.centres, body.radii, body.velocities)
        intent = MotionIntent(qdot=qdot, carrying=None, moving=True, rate=1.0)
        monitor = assess(
            pipeline,
            q,
            qdot,
            body,
            intent,
            safety,
            options.joint_acceleration_limit,
            0.045,
            period,
            2 * period,
        )
        assert settings.scale(*args) == monitor.limit
        seen.append(monitor.limit)
    assert pipeline.robot(q, 0.045, None) is pipeline.pairs(q, 0.045, None, body).robot
    assert len(set(seen)) > 1
