"""A simulated RG2 behind a Modbus TCP server on the loopback (for tests/test_rg2_modbus.py).

The gripper is the station's own (`hrc_drake.cell.station.gripper`: the force-limited
`FingerServo`, the clipped command, the `GripSensor` with the RG2's "stopped short" rule) in a
Drake diagram of its own: the RG2 model welded to the world, with the default scenario's plant,
contact materials and finger gains, and, if asked, a block between its pads that stops them at
`block_width`. A pymodbus TCP server on 127.0.0.1 holds the Compute Box's registers
(docs/hardware.md) as unit 65, and a task in the server's event loop steps the diagram paced to
the wall clock: while register 2 says grip it takes registers 0-1 as the target (stop: where the
fingers are), and it writes the measured width to 267 and the status (busy while the fingers
move and for `ACCEPT_BUSY` after a new target, grip detected) to 268. It takes a new target at
once, busy or not (what a real Compute Box does with a target sent while busy is not known
here)."""

from __future__ import annotations

import asyncio
import socket
import threading
import time

import numpy as np
from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from hrc_drake.cell.scenario import plant_config, scene_graph_config
from hrc_drake.cell.station.faults import STILL_RATE
from hrc_drake.cell.station.gripper import add_gripper_ports, set_finger_gains
from hrc_drake.drivers.rg2_modbus import (
    ACTUAL_WIDTH,
    BUSY,
    FORCE_PER_NEWTON,
    GRIP,
    GRIP_DETECTED,
    GRIP_WITH_OFFSET,
    STOP,
    TARGET_FORCE,
    WIDTH_PER_METRE,
)
from hrc_drake.resources import package_uri
from hrc_drake.rg2_kinematics import pad_height
from hrc_drake.robot_models import make_parser, set_rg2_opening
from hrc_drake.scenario.schema import Scenario

UNIT = 65
# Busy from taking a new target until the fingers have had this long to set off [s] (our choice:
# a Compute Box flags busy as it accepts a grip command, before its fingers move; without it a
# poll right after the command, while this server lags under load, read the fingers still at
# their start and not busy: "done", with a grip detected at the old width).
ACCEPT_BUSY = 0.1
READ_HOLDING, WRITE_MULTIPLE = 3, 16  # Modbus function codes


class SimulatedRg2:
    """The station's gripper alone in a diagram; `advance(opening, force, t)` steps it to time
    `t` [s] with that command and gives (opening [m], rate [m/s], grip detected)."""

    def __init__(self, block_width: float | None = None, scenario: Scenario | None = None):
        scenario = scenario or Scenario()
        gripper = scenario.station.rg2
        builder = DiagramBuilder()
        plant, _ = AddMultibodyPlant(plant_config(scenario), scene_graph_config(scenario), builder)
        (rg2,) = make_parser(plant).AddModels(url=package_uri("rg2/rg2.sdf"))
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("rg2_base", rg2))
        if block_width is not None:  # compliant (the scene's default), the pads rigid
            plant.RegisterCollisionGeometry(
                plant.world_body(),
                RigidTransform([0.0, 0.0, pad_height(block_width)]),  # where the pads meet it
                Box(0.03, block_width, 0.02),
                "block",
                CoulombFriction(1.0, 1.0),
            )
        set_finger_gains(plant, rg2, gripper.kp, gripper.kd)
        # Unlike the station's, the fingers here have their weight (the servo holds it, a few
        # micrometres off): with nothing else in the plant, SAP needs an impulse that is not zero
        # to converge with the linkage's couplers at rest (all of them zero, it may not: measured,
        # 20 of 33 commands, 11 openings x 3 forces, failed once the fingers stopped; with the
        # weight, none). The station's parts resting on the cell give it that impulse.
        plant.Finalize()
        set_rg2_opening(plant, None, gripper.initial_opening, rg2)
        add_gripper_ports(builder, plant, rg2, gripper.kp)
        self._diagram = builder.Build()
        self._simulator = Simulator(self._diagram)
        self._context = self._simulator.get_mutable_context()
        self.plant, self.plant_context = plant, plant.GetMyContextFromRoot(self._context)
        self.initial = (gripper.initial_opening, gripper.grip_force)
        self._simulator.Initialize()

    def advance(self, opening: float, force: float, t: float) -> tuple[float, float, bool]:
        """Step to `t` [s] commanding `opening` [m] and `force` [N]."""
        d, ctx = self._diagram, self._context
        d.GetInputPort("rg2.opening").FixValue(ctx, [opening])
        d.GetInputPort("rg2.force").FixValue(ctx, [force])
        if t > ctx.get_time():
            self._simulator.AdvanceTo(t)
        measured = d.GetOutputPort("rg2.state_measured").Eval(ctx)
        grip = d.GetOutputPort("rg2.grip_detected").Eval(ctx)[0] > 0.5
        return float(measured[0]), float(measured[1]), bool(grip)


def free_port() -> int:
    """A TCP port on the loopback no one listens on now."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class Rg2ModbusServer:
    """A pymodbus TCP server on 127.0.0.1:`port` holding the RG2's registers, driven by
    `device` every `period` [s] of the wall clock, in a thread of its own (`start`, `stop`, or
    a context manager). `targets` lists the targets (opening, force) the device took, in order."""

    def __init__(self, device: SimulatedRg2, period: float = 0.01):
        self.device, self.period = device, period
        self.port = free_port()
        self.targets: list[tuple[float, float]] = []
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._server: ModbusTcpServer | None = None
        self._task: asyncio.Task | None = None

    def __enter__(self) -> Rg2ModbusServer:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> None:
        """Serve, and start the device."""
        self._thread.start()
        self._call(self._start())

    async def _start(self) -> None:
        device = SimDevice(
            UNIT,
            simdata=[
                SimData(TARGET_FORCE, values=[0, 0, 0], datatype=DataType.REGISTERS),
                SimData(ACTUAL_WIDTH, values=[0, 0], datatype=DataType.REGISTERS),
            ],
        )
        self._server = ModbusTcpServer(device, address=("127.0.0.1", self.port))
        await self._server.serve_forever(background=True)
        self._task = asyncio.ensure_future(self._run())

    def stop(self) -> None:
        """Stop the device and the server, and the thread."""
        if self._server is not None:
            self._call(self._stop())
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)

    async def _stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
        await self._server.shutdown()

    def registers(self, address: int, count: int) -> list[int]:
        """The values of `count` registers from `address` (from another thread)."""
        return self._call(self._server.async_getValues(UNIT, READ_HOLDING, address, count))

    def _call(self, coroutine):
        return asyncio.run_coroutine_threadsafe(coroutine, self._loop).result(timeout=10)

    async def _run(self) -> None:
        server, start = self._server, time.monotonic()
        opening, force = self.device.initial
        measured, accepted = opening, -ACCEPT_BUSY
        while True:
            register_force, width, control = await server.async_getValues(
                UNIT, READ_HOLDING, TARGET_FORCE, 3
            )
            target = opening, force
            if control in (GRIP, GRIP_WITH_OFFSET):
                target = width / WIDTH_PER_METRE, register_force / FORCE_PER_NEWTON
            elif control == STOP:
                target = measured, force
            now = time.monotonic() - start
            if target != (opening, force) or not self.targets:
                self.targets.append(target)
                accepted = now
            opening, force = target
            measured, rate, grip = self.device.advance(opening, force, now)
            busy = abs(rate) > STILL_RATE or now - accepted < ACCEPT_BUSY
            status = (BUSY if busy else 0) | (GRIP_DETECTED if grip else 0)
            width_now = int(np.clip(round(measured * WIDTH_PER_METRE), 0, 0xFFFF))
            await server.async_setValues(UNIT, WRITE_MULTIPLE, ACTUAL_WIDTH, [width_now, status])
            await asyncio.sleep(self.period)
