"""Plans across processes: exact plain-data round trips (plan_io) and the plan services that let
a controller plan beside its update (a worker process, or inline for tests)."""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import pickle
import signal
import struct
import time

import numpy as np
import pytest
from pydrake.trajectories import PiecewiseQuaternionSlerp

from hrc_drake.cell_models import CellDesign, CellModelError
from hrc_drake.motion import MotionOptions, MotionPlanner, Plan
from hrc_drake.motion.plan_io import (
    plan_from_data,
    plan_to_data,
    trajectory_to_data,
)
from hrc_drake.motion.plan_request import PlanFailure, PlanRequest
from hrc_drake.motion.plan_worker import FrameReader as _FrameReader
from hrc_drake.motion.plan_worker import FrameWriter as _FrameWriter
from hrc_drake.motion.service import (
    InlinePlanService,
    PlanServiceError,
    WorkerPlanService,
    planner_function,
    shared_plan_service,
)
from hrc_drake.tasks.spec import load_spec
from hrc_drake.tasks.tokens import UNDO

# (configuration, task, last token, measured layout): assembly from the empty base, a flange on
# the square, undo of a flange on the plate and of one on the square, and a square where the
# operator put the other oval first (a measured layout that is not the robot's routine).
REQUESTS = (
    PlanRequest.of(frozenset(), "S12"),
    PlanRequest.of({"S23"}, "F02", "S23"),
    PlanRequest.of({"F1"}, UNDO, "F1"),
    PlanRequest.of({"S23", "F03"}, UNDO, "F03"),
    PlanRequest.of({"F1"}, "S23", "F1", {"oval_flange_2": "F1"}),
)


def _design(**layout) -> CellDesign:
    design = CellDesign.of(load_spec())
    return CellDesign.of(design.spec, dataclasses.replace(design.layout, **layout))


def _plan(planner: MotionPlanner, request: PlanRequest) -> Plan:
    return planner.plan_task(
        request.configuration,
        request.task,
        last_token=request.last_token,
        layout=request.layout_map(),
    )


def assert_same_plan(a: Plan, b: Plan, samples: int = 2000) -> None:
    """Same fields; arm and gripper equal in value and first derivative at many times (pieces'
    ends included), to 1e-12."""
    for field in dataclasses.fields(Plan):
        if field.name not in ("trajectory", "gripper"):
            assert getattr(a, field.name) == getattr(b, field.name), field.name
    times = np.concatenate(
        [
            np.linspace(-0.5, a.duration + 0.5, samples),
            a.trajectory.get_segment_times(),
            [s.start for s in a.segments],
        ]
    )
    for trajectory in ("trajectory", "gripper"):
        x, y = getattr(a, trajectory), getattr(b, trajectory)
        assert (x.start_time(), x.end_time()) == (y.start_time(), y.end_time())
        for derivative in (0, 1):
            np.testing.assert_allclose(
                [x.EvalDerivative(t, derivative) for t in times],
                [y.EvalDerivative(t, derivative) for t in times],
                rtol=0,
                atol=1e-12,
                err_msg=f"{trajectory}, derivative {derivative}",
            )


@pytest.fixture(scope="module")
def planner():
    return MotionPlanner()


@pytest.fixture(scope="module", autouse=True)
def worker():
    """The process-wide worker for the flange cell, started once for the module and set to
    plan REQUESTS while the module's first tests run."""
    service = shared_plan_service(MotionOptions(), CellDesign.of(load_spec()))
    # In the other order than the in-process planner plans them: each plan is reseeded.
    for request in reversed(REQUESTS):
        service.request(request)
    yield service
    service.close()


# plan_io


@pytest.mark.parametrize("request_", REQUESTS, ids=lambda r: f"{sorted(r.configuration)}:{r.task}")
def test_a_plan_round_trips_exactly_through_plain_data(planner, request_):
    plan = _plan(planner, request_)
    again = plan_from_data(plan_to_data(plan))
    assert_same_plan(again, plan)
    # The rebuilt tree is the original's: the same pieces at the same times.
    np.testing.assert_array_equal(
        again.trajectory.get_segment_times(), plan.trajectory.get_segment_times()
    )


def test_plan_data_of_another_format_is_refused(planner):
    plan = planner.plan_task(frozenset(), "S12")
    with pytest.raises(ValueError, match="format"):
        plan_from_data({**plan_to_data(plan), "format": 99})


def test_an_unknown_trajectory_type_is_named():
    with pytest.raises(TypeError, match="PiecewiseQuaternionSlerp"):
        trajectory_to_data(PiecewiseQuaternionSlerp())


# PlanRequest and the inline service


def test_requests_that_get_the_same_plan_have_the_same_key():
    layout = {"square_flange": "S23"}
    # With a measured layout, the task done last matters only to undo.
    assert (
        PlanRequest.of({"S23"}, "F1", "S23", layout).key()
        == PlanRequest.of({"S23"}, "F1", None, layout).key()
    )
    assert PlanRequest.of({"S23"}, UNDO, "S23", layout) != PlanRequest.of({"S23"}, UNDO, None)
    # Without one, the routine layout depends on it.
    assert PlanRequest.of({"S23"}, "F1", "S23").key() != PlanRequest.of({"S23"}, "F1").key()


def test_inline_service_plans_at_once_with_its_function(planner):
    calls = []

    def misplacing(configuration, task, last, layout):
        calls.append(task)
        if task == "F02":  # the plan of F03 under F02's name: the robot misplaces the part
            return dataclasses.replace(
                planner.plan_task(configuration, "F03", layout=layout), task="F02"
            )
        return planner_function(planner)(configuration, task, last, layout)

    service = InlinePlanService(misplacing)
    wrong, bad = PlanRequest.of({"S23"}, "F02", "S23"), PlanRequest.of({"F1"}, "F1")
    with pytest.raises(ValueError, match="never requested"):
        service.poll(wrong)
    assert not service.is_cached(wrong)
    service.request(wrong)
    service.request(wrong)
    assert service.is_cached(wrong) and calls == ["F02"]
    plan = service.poll(wrong)
    assert plan.task == "F02" and plan.t_in_place > 0
    np.testing.assert_array_equal(
        plan.positions(plan.t_in_place),
        planner.plan_task({"S23"}, "F03").positions(plan.t_in_place),
    )
    service.request(bad)
    failure = service.poll(bad)
    assert isinstance(failure, PlanFailure)
    assert (failure.task, failure.kind) == ("F1", "ValueError")
    assert "already in place" in str(failure)


# The worker process


def test_the_worker_plans_what_an_in_process_planner_plans(worker, planner):
    np.testing.assert_array_equal(worker.q_home, planner.q_home)
    worker.check_reach()
    for request in REQUESTS:
        result = worker.wait(request, timeout=120.0)
        assert isinstance(result, Plan), result
        assert_same_plan(result, _plan(planner, request))
        assert worker.is_cached(request)
        assert worker.worker_seconds(request) > 0.0


def test_the_worker_answers_later_and_rebuilds_a_few_pieces_per_poll(worker):
    request = PlanRequest.of(frozenset(), "F3")
    assert not worker.is_cached(request)
    worker.request(request)
    # The plan takes a fifth of a second or more: request returned before it was made.
    assert worker.poll(request) is None
    deadline = time.monotonic() + 120.0
    while not worker.is_cached(request):
        assert worker.alive and time.monotonic() < deadline
        time.sleep(0.01)
    worker.rebuild_budget = 0.0  # one piece of the arm trajectory per poll
    try:
        polls = 1
        while (plan := worker.poll(request)) is None:
            polls += 1
    finally:
        worker.rebuild_budget = 0.001
    assert polls == plan.trajectory.get_number_of_segments() + 1
    assert worker.poll(request) is plan


def test_worker_failures_come_back_as_values(worker):
    request = PlanRequest.of({"F1"}, "F1")
    failure = worker.wait(request, timeout=60.0)
    assert isinstance(failure, PlanFailure)
    assert failure.kind == "ValueError" and "task F1 is already in place" in failure.reason
    assert worker.alive  # a failed plan does not end the worker


def test_a_half_written_result_does_not_block_the_reader():
    # The worker may be descheduled in the middle of writing a plan; the parent's poll must
    # return meanwhile, not wait for the rest.
    context = multiprocessing.get_context("spawn")
    parent_end, worker_end = context.Pipe(duplex=False)
    reader, writer = _FrameReader(parent_end), _FrameWriter(worker_end)
    message = ("plan", 7, {"coefficients": bytes(range(256)) * 400}, 0.25)
    payload = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    frame = struct.pack("<Q", len(payload)) + payload
    os.write(worker_end.fileno(), frame[: len(frame) // 2])
    assert reader.messages() == []
    os.write(worker_end.fileno(), frame[len(frame) // 2 :])
    writer.put(("started", 8))
    assert reader.messages() == [message, ("started", 8)]
    worker_end.close()
    assert reader.messages() == [] and reader.eof
    reader.close()


def test_the_same_cell_and_options_share_one_worker(worker):
    assert shared_plan_service(MotionOptions(), CellDesign.of(load_spec())) is worker


def test_an_unreachable_slot_and_a_dead_worker_are_clear_errors():
    # Slot 3 of a plate moved 0.35 m to the side is 0.52 m from the UR3's base axis.
    aside = _design(plate_position=[0.30, 0.35, 0.0], tray_position=[0.2, -0.25, 0.0])
    service = shared_plan_service(MotionOptions(), aside)
    try:
        with pytest.raises(CellModelError, match=r"cannot reach F3 \(slot 3\)"):
            service.check_reach()
        failure = service.wait(PlanRequest.of(frozenset(), "F3"), timeout=120.0)
        assert isinstance(failure, PlanFailure) and failure.kind == "UnreachableError"
        assert failure.reason.startswith("task F3: the pre-place pose is unreachable")

        busy = PlanRequest.of(frozenset(), "F1")
        service.request(busy)
        os.kill(service.pid, signal.SIGKILL)
        service._process.join(10.0)
        with pytest.raises(PlanServiceError, match=r"killed by signal 9.*pending: F1"):
            service.poll(busy)
        with pytest.raises(PlanServiceError, match="closed"):
            service.request(PlanRequest.of(frozenset(), "F2"))
        # The shared service of that cell is replaced, not handed out dead.
        again = shared_plan_service(MotionOptions(), aside)
        assert again is not service
        again.close()
    finally:
        service.close()


def test_a_cell_too_far_for_the_home_pose_is_refused_at_start():
    service = WorkerPlanService(MotionOptions(), _design(plate_position=[0.62, 0.0, 0.0]))
    with pytest.raises(CellModelError, match=r"home pose .*cell\.plate_position"):
        _ = service.q_home
    assert not service.alive
