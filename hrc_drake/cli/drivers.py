"""`hrc-drake drivers`: the real devices a scenario's `drivers:` section names
(`hrc_drake.scenario.drivers`), each served on the station's LCM channels by its driver's
bridge, until Ctrl-C or SIGTERM.

Every device is connected before any is served: one that cannot be reached ends the command
with one line naming it, host:port and the fix (exit status 1), the others closed again. Each
bridge then runs in a thread of its own (both poll their LCM without waiting, so neither holds
the GIL from the other; ur_rtde's `waitPeriod` releases it); a bridge that fails stops the
others (exit status 1), and the arm is always left stopped (`servoStop`). A scenario with no
device on real hardware is refused (exit status 2), and so is `hrc-drake station` with a
scenario that has one (`refuse_real_devices`): the simulated station cannot serve half a cell.

The drivers (Drake, pymodbus, ur_rtde) are imported when the command runs, not with the CLI.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shlex
import signal
import sys
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass

from hrc_drake.paths import UsageError
from hrc_drake.scenario.drivers import Rg2Modbus, UrRtde
from hrc_drake.scenario.schema import Scenario

EXIT_NOTHING = 2  # a scenario with nothing to drive: as for an option refused
JOIN_TIMEOUT = 5.0  # s a bridge's thread may take to end after the stop (a Modbus timeout)
_POLL = 0.2  # s between the main thread's looks at the stop event


class DriverUnreachable(RuntimeError):
    """A device the scenario puts on real hardware that cannot be connected (or driven)."""


@dataclass
class Served:
    """One device served: its `key` in the scenario (`drivers.rg2`), the line saying what it
    serves and where, and its bridge's `run(stop)`, `close()` and `counts()`."""

    key: str
    line: str
    run: Callable[[threading.Event], None]
    close: Callable[[], None]
    counts: Callable[[], dict[str, int]]


def drivers_hint(scenario_args: list[str], url: str) -> str:
    """The command that serves a scenario's real devices on `url`, to paste into a shell."""
    return shlex.join(["hrc-drake", "drivers", *scenario_args, "--lcm", url])


def refuse_real_devices(scenario: Scenario, scenario_args: list[str], url: str) -> None:
    """UsageError (for `hrc-drake station`) when `scenario` puts any device on real hardware:
    one line naming the devices and the `hrc-drake drivers` command that serves them."""
    real = scenario.drivers.on_hardware()
    if not real:
        return
    named = ", ".join(f"drivers.{name} (!{type(d).__name__})" for name, d in real.items())
    raise UsageError(
        f"scenario {scenario.name} puts {named} on real hardware, and the simulated station "
        "cannot serve half a cell: serve the real devices with "
        f"`{drivers_hint(scenario_args, url)}`, or make them !Simulated {{}}"
    )


def _connect_ur3(config: UrRtde, url: str) -> Served:
    from pydrake.lcm import DrakeLcm

    try:
        from hrc_drake.drivers.ur3_rtde import Ur3Bridge, Ur3DriverError, Ur3RtdeDriver

        driver = Ur3RtdeDriver(config.settings())
    except ImportError as err:
        raise DriverUnreachable(
            f"drivers.ur3 needs ur_rtde ({err}): pip install -e '.[hardware]'"
        ) from err
    except Ur3DriverError as err:
        raise DriverUnreachable(f"drivers.ur3: {err}") from err
    bridge = Ur3Bridge(driver, DrakeLcm(url))
    return Served(
        key="drivers.ur3",
        line=f"{config.describe()} serves UR3_COMMAND and UR3_STATUS on {url}",
        run=lambda stop: bridge.run(stop=stop),
        close=driver.close,
        counts=dict,
    )


def _connect_rg2(config: Rg2Modbus, url: str) -> Served:
    from pydrake.lcm import DrakeLcm

    try:
        from hrc_drake.drivers.rg2_modbus import Rg2ConnectionError, Rg2LcmBridge
        from hrc_drake.drivers.rg2_modbus import Rg2Modbus as Rg2Driver
    except ImportError as err:
        raise DriverUnreachable(
            f"drivers.rg2 needs pymodbus ({err}): pip install -e '.[hardware]'"
        ) from err
    settings = config.settings()
    driver = Rg2Driver(settings)
    try:
        driver.connect()
    except Rg2ConnectionError as err:
        raise DriverUnreachable(
            f"drivers.rg2: {err}; the scenario's drivers.rg2 gives host, port and unit"
        ) from err
    bridge = Rg2LcmBridge(driver, DrakeLcm(url))
    return Served(
        key="drivers.rg2",
        line=(
            f"{config.describe()} serves RG2_COMMAND and RG2_STATUS on {url} at "
            f"{settings.poll_rate:g} Hz"
        ),
        run=bridge.run,
        close=driver.close,
        counts=lambda: {
            "published": bridge.published,
            "commands": bridge.commands,
            "refused": len(bridge.refused),
        },
    )


@contextlib.contextmanager
def _stderr_kept(said: list[str]):
    """Keep what is written to stderr meanwhile (file descriptor 2, and Python's `sys.stderr`)
    in `said`, line by line: the devices' libraries tell of a failed connection there
    themselves (ur_rtde from C++, pymodbus by its logger), which would come before the
    command's one line. Only while no other thread runs (the devices are connected before the
    bridges start)."""
    sys.stderr.flush()
    saved, logged = os.dup(2), io.StringIO()
    with tempfile.TemporaryFile(mode="w+b") as kept:
        os.dup2(kept.fileno(), 2)
        try:
            with contextlib.redirect_stderr(logged):  # Python's own writes (a logger's)
                yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            kept.seek(0)
            text = kept.read().decode(errors="replace") + logged.getvalue()
            said.extend(line.strip() for line in text.splitlines() if line.strip())


def _connect(name: str, config: UrRtde | Rg2Modbus, url: str) -> Served:
    """Connect one device; DriverUnreachable with what its library said, in one line."""
    connect = _connect_ur3 if name == "ur3" else _connect_rg2
    said: list[str] = []
    try:
        with _stderr_kept(said):
            served = connect(config, url)
    except DriverUnreachable as err:
        if not said:
            raise
        raise DriverUnreachable(f"{err} (the library said: {'; '.join(said)})") from err
    if said:
        print("\n".join(said), file=sys.stderr)  # connected: what it said is news
    return served


def connect_all(scenario: Scenario, url: str) -> list[Served]:
    """Connect every device `scenario` puts on real hardware, in the section's order;
    DriverUnreachable for the first that cannot be, the ones connected before closed again."""
    served: list[Served] = []
    try:
        for name, config in scenario.drivers.on_hardware().items():
            served.append(_connect(name, config, url))
    except BaseException:
        for device in served:
            device.close()
        raise
    return served


def _bridge(device: Served, stop: threading.Event, errors: list[str]) -> None:
    """A bridge's thread: run it until `stop`; an error is kept and stops every bridge."""
    try:
        device.run(stop)
    except Exception as err:  # a driver's error ends its bridge; report it, stop the rest
        errors.append(f"{device.key}: {err}")
    finally:
        stop.set()


def serve_all(served: list[Served], stop: threading.Event) -> list[str]:
    """Run each bridge in a thread of its own until `stop` is set (by a signal, or by a bridge
    that failed), then close every device; the bridges' errors."""
    errors: list[str] = []
    threads = [
        threading.Thread(target=_bridge, args=(d, stop, errors), name=d.key, daemon=True)
        for d in served
    ]
    for thread in threads:
        thread.start()
    try:
        while not stop.wait(_POLL):
            pass
    finally:
        stop.set()
        for thread in threads:
            thread.join(JOIN_TIMEOUT)
        for device in served:
            try:
                device.close()  # the arm: servoStop, then ur_rtde's script ended
            except Exception as err:  # closing one must not keep the others open
                errors.append(f"{device.key}: while closing: {err}")
    return errors


def _stop_on_signals(stop: threading.Event) -> dict:
    """Set `stop` on SIGINT and SIGTERM (the previous handlers, to restore)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        previous[sig] = signal.signal(sig, lambda *_: stop.set())
    return previous


def _summary(scenario: Scenario, url: str, served: list[Served], as_json: bool) -> None:
    counts = {d.key: d.counts() for d in served}
    if as_json:
        devices = [{"key": d.key, "serves": d.line, **counts[d.key]} for d in served]
        print(json.dumps({"scenario": scenario.name, "lcm": url, "devices": devices}))
        return
    for device in served:
        told = ", ".join(f"{k} {v}" for k, v in counts[device.key].items())
        print(f"{device.key}: stopped" + (f" ({told})" if told else ""))


def drivers_command(args) -> int:
    """`hrc-drake drivers`: serve the scenario's real devices on `--lcm` until Ctrl-C or
    SIGTERM (exit status 0); 1 if a device cannot be reached or fails while served; 2 if the
    scenario puts nothing on real hardware."""
    from hrc_drake.cell.link.lockstep import check_lcm_url
    from hrc_drake.cell.scenario import lcm_url, load_cell_scenario

    scenario = load_cell_scenario(args.scenario, args.scenario_text)
    url = check_lcm_url(args.lcm or lcm_url(scenario), "--lcm")
    if not scenario.drivers.on_hardware():
        print(
            f"hrc-drake drivers: error: nothing to drive: drivers.ur3 and drivers.rg2 are "
            f"!Simulated in scenario {scenario.name or '<defaults>'}; give a scenario that puts "
            "a device on real hardware (!UrRtde, !Rg2Modbus)",
            file=sys.stderr,
        )
        return EXIT_NOTHING
    stop = threading.Event()
    previous = _stop_on_signals(stop)
    try:
        served = connect_all(scenario, url)
        for device in served:
            print(f"hrc-drake drivers: {device.line}", file=sys.stderr, flush=True)
        print("hrc-drake drivers: serving; Ctrl-C or SIGTERM stops", file=sys.stderr, flush=True)
        errors = serve_all(served, stop)
    except DriverUnreachable as err:
        print(f"hrc-drake drivers: error: {err}", file=sys.stderr)
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    _summary(scenario, url, served, args.json)
    for error in errors:
        print(f"hrc-drake drivers: error: {error}", file=sys.stderr)
    return 1 if errors else 0


__all__ = [
    "EXIT_NOTHING",
    "DriverUnreachable",
    "Served",
    "connect_all",
    "drivers_command",
    "drivers_hint",
    "refuse_real_devices",
    "serve_all",
]
