"""The separation monitor the cell had before the controller got its own (the benchmark's
baseline, `bench_separation.py`): it reads the simulator's scene graph, which a real controller
does not have. The cell's monitor is
`hrc_drake.cell.controller.separation.ControllerSeparationMonitor`.

Speed and separation monitoring (ISO/TS 15066 §5.5.4) between the robot and the operator.

At every Supervisor update the `SeparationMonitor` takes, for each sphere of the operator's body,
the nearest robot geometry (the UR3's and the gripper's collision geometry, and the part the
gripper holds) with `QueryObject.ComputeSignedDistanceToPoint`, which ignores collision filters,
and the robot's velocity toward the sphere at that nearest point (the point's Jacobian). With
them it evaluates the protective separation distance

    S_p = v_h (T_r + T_s) + v_r T_r + S_s + C + Z_d + Z_r

(ISO/TS 15066:2016 §5.5.4.2; the worked example of Marvel & Norcross 2017, "Implementing speed
and separation monitoring in collaborative robot workcells", Robot. Comput.-Integr. Manuf. 44).
The stopping time and distance come from the arm's joint acceleration limit a (MotionOptions): the
robot stops along its path by scaling its trajectory's time, so every joint decelerates together
and the fastest one sets the time, T_s = max_j |q̇_j| / a; a point's speed then falls linearly to
zero, S_s = v_r T_s / 2.

`speed_limit` (the Supervisor's input) is the largest speed scale s ∈ [0, 1] of the plan at which
every sphere is at least S_p(s) + `slow_band` away, with the plan's own velocities scaled by s
(S_p is quadratic in s): 1 is full speed, 0 a stop. The monitor's update logs each step
(`SafetyLog`): least separation, least margin (separation − S_p with the measured velocities) while
the robot moves, violations (steps where the robot moved with separation < S_p), body contacts,
and the time spent slowed and stopped.

The reading, the log and `allowed_scale` are those of the controller's monitor
(`hrc_drake.cell.controller.separation`), which reads only what a real cell measures.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Role
from pydrake.multibody.tree import BodyIndex, JacobianWrtVariable
from pydrake.systems.framework import BasicVector, LeafSystem

from hrc_drake.cell.controller.separation import (
    CONTACT_SHARE,
    SafetyLog,
    SeparationReading,
    planned_scales,
)
from hrc_drake.cell.controller.supervisor import Mode, SupervisorStatus
from hrc_drake.cell.person import CHAIN_GAP
from hrc_drake.cell.ports import NOBODY, BodySpheres
from hrc_drake.cell.ssm import allowed_scale, person_travel
from hrc_drake.motion.plan import Stage
from hrc_drake.scenario.safety import SafetyConfig

REACH = 0.8  # m; farther than S_p can be here (v_h ≤ 2 m/s, T_s ≤ 0.2 s at 0.25 m/s TCP)
EXACT = 0.25  # m; the least separation is exact below this, a lower bound above


class SeparationMonitor(LeafSystem):
    """Separation between the robot and the operator's body, S_p, and the speed scale allowed.

    Input ports: `plant_state`, `query_object`, `body` (BodySpheres), `status`
    (SupervisorStatus). Output port: `speed_limit` (1) and `reading` (SeparationReading). The
    log is the abstract state `log` (`SeparationMonitor.log(context)`)."""

    def __init__(
        self,
        plant,
        scene_graph,
        robot_instances,
        part_instances: dict[str, object],
        config: SafetyConfig,
        joint_acceleration: float,
        period: float,
    ):
        super().__init__()
        self._plant, self._config = plant, config
        self._acc, self._period = joint_acceleration, period
        self._context = plant.CreateDefaultContext()
        inspector = scene_graph.model_inspector()
        proximity = set(inspector.GetAllGeometryIds(Role.kProximity))
        # geometry -> body it moves with; a held part's geometry moves with the gripper.
        self._robot_geometry: dict = {}
        for model in robot_instances:
            for index in plant.GetBodyIndices(model):
                body = plant.get_body(index)
                for gid in plant.GetCollisionGeometriesForBody(body):
                    if gid in proximity:
                        self._robot_geometry[gid] = body
        self._tcp_body = plant.GetFrameByName("tcp", robot_instances[1]).body()
        self._part_geometry: dict = {}
        for name, model in part_instances.items():
            body = plant.get_body(BodyIndex(int(plant.GetBodyIndices(model)[0])))
            for gid in plant.GetCollisionGeometriesForBody(body):
                self._part_geometry[gid] = name
        arm = robot_instances[0]
        self._arm_v = np.concatenate(
            [
                np.arange(j.velocity_start(), j.velocity_start() + j.num_velocities())
                for j in (plant.get_joint(i) for i in plant.GetJointIndices(arm))
                if j.num_velocities() > 0
            ]
        ).astype(int)
        self._state_port = self.DeclareVectorInputPort(
            "plant_state", BasicVector(plant.num_multibody_states())
        )
        self._query_port = self.DeclareAbstractInputPort(
            "query_object", scene_graph.get_query_output_port().Allocate()
        )
        self._body_port = self.DeclareAbstractInputPort("body", AbstractValue.Make(NOBODY))
        self._status_port = self.DeclareAbstractInputPort(
            "status", AbstractValue.Make(SupervisorStatus())
        )
        self._reading_port = self.DeclareAbstractOutputPort(
            "reading", lambda: AbstractValue.Make(SeparationReading()), self._calc_reading
        )
        self.DeclareVectorOutputPort("speed_limit", BasicVector(1), self._calc_limit)
        self._log_index = self.DeclareAbstractState(AbstractValue.Make(SafetyLog()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    def log(self, context) -> SafetyLog:
        """The log in this system's context."""
        return context.get_abstract_state(self._log_index).get_value()

    def _calc_limit(self, context, output) -> None:
        output.SetFromVector([self._reading_port.Eval(context).limit])

    def _nominal_qdot(self, status: SupervisorStatus, now: float) -> np.ndarray:
        """The arm's joint velocities at the plan's own speed (s = 1)."""
        if status.mode != Mode.EXECUTE or status.plan is None:
            return np.zeros(len(self._arm_v))
        tau = status.plan_time(now)
        return status.plan.trajectory.EvalDerivative(tau, 1).ravel()

    def _nearest(self, query, centre: np.ndarray, radius: float, held: set[str]):
        """(gap, witness point in world, body) of the robot geometry nearest the sphere, or
        None if none is within REACH."""
        best = None
        for d in query.ComputeSignedDistanceToPoint(centre, REACH + radius):
            body = self._robot_geometry.get(d.id_G)
            if body is None and self._part_geometry.get(d.id_G) in held:
                body = self._tcp_body
            if body is not None and (best is None or d.distance < best[0]):
                best = (d.distance, d.id_G, d.p_GN, body)
        if best is None:
            return None
        # A chain of spheres is thinner than its capsule between spheres (`_chain`).
        gap = best[0] - radius * (1 + CHAIN_GAP)
        return gap, query.GetPoseInWorld(best[1]) @ best[2], best[3]

    def _assess(self, hits, centres, human, v_meas, qdot_nom):
        """Per hit: (S_p with the measured velocities, the speed scale allowed)."""
        cfg, plant = self._config, self._plant
        n = len(hits)
        gap = np.array([h[0] for h in hits])
        v_nom, v_now = np.zeros((n, 3)), np.zeros((n, 3))
        bodies = {h[2].index(): h[2] for h in hits}
        for index, body in bodies.items():
            rows = [k for k, h in enumerate(hits) if h[2].index() == index]
            X_WB = plant.EvalBodyPoseInWorld(self._context, body)
            p_BN = X_WB.inverse() @ np.array([hits[k][1] for k in rows]).T
            J = plant.CalcJacobianTranslationalVelocity(
                self._context,
                JacobianWrtVariable.kV,
                body.body_frame(),
                p_BN,
                plant.world_frame(),
                plant.world_frame(),
            )[:, self._arm_v]
            v_nom[rows] = (J @ qdot_nom).reshape(-1, 3)
            v_now[rows] = (J @ v_meas).reshape(-1, 3)
        toward = centres - np.array([h[1] for h in hits])
        toward /= np.maximum(np.linalg.norm(toward, axis=1, keepdims=True), 1e-9)
        v_h = -np.sum(human * toward, 1)  # signed: a hand moving away must turn first
        const = cfg.intrusion + cfg.human_uncertainty + cfg.robot_uncertainty
        t_r, t_rp = cfg.reaction_time, cfg.reaction_time + self._period
        # Measured: the S_p the standard asks to keep.
        t_s = np.abs(v_meas).max(initial=0.0) / self._acc
        v_r = np.maximum(0.0, np.sum(v_now * toward, 1))
        s_p = person_travel(v_h, gap, t_r + t_s, cfg) + v_r * t_r + v_r * t_s / 2 + const
        # Planned at scale s: S_p(s) = a0 + a1 s + a2 s^2 (the function's sampling period
        # added to the reaction), or no faster toward the body than the contact speed.
        t_s1 = np.abs(qdot_nom).max(initial=0.0) / self._acc
        v_r1 = np.maximum(0.0, np.sum(v_nom * toward, 1))
        separated = planned_scales(v_h, gap, v_r1, t_rp, t_s1, cfg, gap - cfg.slow_band)
        slow = np.minimum(CONTACT_SHARE * cfg.contact_speed / np.maximum(v_r1, 1e-9), 1.0)
        return s_p, np.maximum(separated, slow)

    def _calc_reading(self, context, output) -> None:
        cfg, plant = self._config, self._plant
        spheres: BodySpheres = self._body_port.Eval(context)
        status: SupervisorStatus = self._status_port.Eval(context)
        query = self._query_port.Eval(context)
        plant.SetPositionsAndVelocities(self._context, self._state_port.Eval(context))
        v_meas = plant.GetVelocities(self._context)[self._arm_v]
        qdot_nom = self._nominal_qdot(status, context.get_time())
        moving = bool(np.abs(v_meas).max(initial=0.0) > cfg.moving_speed)
        held = {w.part for w in status.welds if w.kind == "grasp"}
        speed = np.linalg.norm(spheres.velocities, axis=1)
        # Branch and bound over each body part's chain of spheres: a range's bounding sphere
        # gives a lower bound on its distance, moving at its fastest sphere's velocity; a range
        # is halved while its bound does not clear it at full speed, or it lies within EXACT and
        # may hold the least separation.
        hits, centres, human = [], [], []
        least = np.inf
        stack = [(start, end) for start, end in reversed(spheres.groups)]
        while stack:
            start, end = stack.pop()
            if end - start == 1:
                hit = self._nearest(query, spheres.centres[start], spheres.radii[start], held)
                if hit is not None:
                    hits.append(hit), centres.append(spheres.centres[start])
                    human.append(spheres.velocities[start])
                    least = min(least, hit[0])
                continue
            a, b = spheres.centres[start], spheres.centres[end - 1]
            centre = (a + b) / 2
            radius = float(np.linalg.norm(b - a) / 2 + spheres.radii[start:end].max())
            hit = self._nearest(query, centre, radius, held)
            if hit is None:
                continue
            v = spheres.velocities[start:end][np.argmax(speed[start:end])]
            s_p, allowed = self._assess([hit], centre[None, :], v[None, :], v_meas, qdot_nom)
            if allowed[0] >= 1.0 and hit[0] - s_p[0] >= 0.0 and hit[0] >= min(least, EXACT):
                hits.append(hit), centres.append(centre), human.append(v)
                continue
            middle = (start + end) // 2
            stack += [(middle, end), (start, middle)]
        if not hits:
            output.set_value(SeparationReading(moving=moving))
            return
        s_p, allowed = self._assess(hits, np.array(centres), np.array(human), v_meas, qdot_nom)
        gap = np.array([h[0] for h in hits])
        output.set_value(
            SeparationReading(
                separation=float(gap.min()),
                margin=float((gap - s_p).min()),
                limit=float(allowed.min()) if cfg.enabled else 1.0,
                moving=moving,
            )
        )

    def _update(self, context, state) -> None:
        reading: SeparationReading = self._reading_port.Eval(context)
        status: SupervisorStatus = self._status_port.Eval(context)
        log = self.log(context)
        log = replace(
            log,
            steps=log.steps + 1,
            min_separation=min(log.min_separation, reading.separation),
            body_contacts=log.body_contacts + int(reading.separation <= 0.0),
        )
        if reading.moving:
            log = replace(
                log,
                min_margin=min(log.min_margin, reading.margin),
                violations=log.violations + int(reading.margin < 0.0),
            )
        if status.mode == Mode.EXECUTE and status.plan is not None:
            tau = status.plan_time(context.get_time())
            hold = [(g.start, g.end) for g in status.plan.segments if g.stage == Stage.HOLD]
            holding = any(start <= tau < end for start, end in hold)
            if not holding and tau < status.plan.duration:
                if status.clock.rate <= 1e-9:
                    log = replace(log, stopped_time=log.stopped_time + self._period)
                elif status.clock.rate < 1.0 - 1e-9:
                    log = replace(log, slowed_time=log.slowed_time + self._period)
        state.get_mutable_abstract_state(self._log_index).set_value(log)


__all__ = ["SafetyLog", "SeparationMonitor", "SeparationReading", "allowed_scale"]
