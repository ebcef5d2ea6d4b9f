"""The lockstep of the cell station over LCM: the protocol the controller's side
(`hrc_drake.cell.link.interface`) and the station's (`hrc_drake.cell.link.station_server`)
follow, and what both use to follow it: the link's errors, its timeouts, the exchange period,
the hello's identity, and the inbox that keeps each channel's newest message.

Lockstep. Both sides are discrete systems whose events fall on multiples of the plant's time step
`h` (the exchange period), and in one process Drake handles the events at a time t in a fixed
order: publish events at the end of the step that reaches t, then every unrestricted update at t
(each computed from the same state), then every discrete update at t. The protocol keeps that
order across the two processes, so that each side reads at each t exactly what it would read in
one diagram; the two-process run then equals the in-process one:

0. Before the first step the controller says which scenario it runs (a "hello" session message
   with its `ScenarioIdentity`, `hrc_drake.cell.link.scenario_identity`), sent again until the
   station answers with its own; each side compares the two, and a pair that differs stops on
   both sides with `ScenarioMismatch`, one line naming what differs. A station that serves no
   scenario (identity None: a real cell's driver, a test's stand-in) answers `{}` and serves any
   controller.
1. At the end of the step reaching t (the interface's publish event) the controller sends its
   commands as they stand before its updates at t, on `<channel>_PRE`, stamped t, and waits for
   the answer (at every exchange, read or not: DrakeLcm keeps only the newest undelivered
   message of a channel, so neither side may send a channel's next message before the other
   has taken the last; for the same reason each direction has channels of its own).
2. The station sets its inputs to them (its outputs with direct feedthrough, e.g. grip detection
   from the commanded opening, and its own unrestricted updates at t read them, as in one
   diagram), and publishes its measurements at t, stamped t.
3. The controller's updates at t read those measurements: the interface's outputs wait for the
   measurements stamped with the context's time (a timeout ends in `StationLinkError`).
4. In the discrete updates at t the controller sends its commands as its unrestricted updates
   left them, on `<channel>`, stamped t: what the station's discrete update at t (the plant's
   step) reads. The station's command hold switches to them in an unrestricted update at t, so
   the station's other unrestricted updates at t still read the commands of step 1.
5. The station advances to t + h (applying its welds through its `Simulator` monitor) and
   waits for step 1 at t + h.

This reproduces the one-process run exactly when the controller's outputs depend on its state
and the time only (no direct feedthrough of the measurements: the Supervisor's do not) and change
only in unrestricted updates, and every update on either side falls on a multiple of h. Lost
datagrams are sent again after `LockstepTimeouts.resend`; a side that does not answer within
`LockstepTimeouts.start` (the first message) or `.step` (each later one) ends the run with a
one-line `StationLinkError`; the station's own errors are sent to the controller and end its
run with the station's message.
"""

from __future__ import annotations

import ipaddress
import json
import re
import shlex
import time
from collections.abc import Callable
from dataclasses import dataclass

from pydrake.lcm import DrakeLcm

from hrc_drake.cell.link.channels import END_CHANNEL, REPORT_CHANNEL, StationChannel
from hrc_drake.cell.link.lcm_messages import lcmt_station_session, session_message
from hrc_drake.cell.link.lcm_struct import LcmDecodeError
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity, mismatch
from hrc_drake.cell.scenario import DEFAULT_LCM_URL, plant_step
from hrc_drake.paths import UsageError
from hrc_drake.scenario.schema import Scenario, ScenarioError


def check_lcm_url(url: str, flag: str) -> str:
    """`url` if it is a UDP multicast LCM URL (the transport between two processes here);
    UsageError naming `flag` otherwise (DrakeLcm takes a bad URL silently, and then nothing
    arrives)."""
    match = re.fullmatch(r"udpm://([0-9.]+):(\d+)(\?.*)?", url)
    try:
        multicast = match is not None and ipaddress.IPv4Address(match[1]).is_multicast
    except ValueError:
        multicast = False
    if not multicast or not 0 < int(match[2]) < 65536:
        raise UsageError(
            f"{flag} {url}: give an LCM UDP multicast URL udpm://GROUP:PORT?ttl=0 with GROUP in "
            f"224.0.0.0-239.255.255.255 and PORT in 1-65535, e.g. {DEFAULT_LCM_URL}"
        )
    return url


class StationLinkError(RuntimeError):
    """The other side of the station link is missing, died, or is out of step."""


class ScenarioMismatch(StationLinkError):
    """The station and the controller were started with different scenarios (or options):
    refused before the first step, on both sides."""


HELLO = "hello"
"""The session message that carries a side's `ScenarioIdentity` (JSON; `{}` for none)."""


LINK = "link"
"""The hello's key for the link's mode: absent in the lockstep, `{"realtime": PACE}` in the
real-time mode (`hrc_drake.cell.link.realtime`)."""


def identity_text(identity: ScenarioIdentity | None, pace: float | None = None) -> str:
    """The text of a hello for `identity`: its JSON, or `{}` (a side that serves any scenario);
    with `pace`, the real-time mode's pace beside it (a lockstep hello has no `link`)."""
    if pace is None:
        return "{}" if identity is None else identity.to_json()
    data = {} if identity is None else json.loads(identity.to_json())
    return json.dumps({**data, LINK: {"realtime": pace}})


def link_pace(message) -> tuple[bool, float | None]:
    """(whether the other side's hello states a mode, its real-time pace or None for the
    lockstep). A hello of `{}` (a real cell's driver, a test's stand-in) states none: it
    serves either mode."""
    try:
        data = json.loads(message.text or "{}")
    except ValueError:
        return False, None  # `their_identity` names what is wrong with it
    if not isinstance(data, dict) or not data:
        return False, None
    link = data.get(LINK)
    pace = link.get("realtime") if isinstance(link, dict) else None
    return True, None if pace is None else float(pace)


def _mode(pace: float | None) -> str:
    return "in lockstep" if pace is None else f"in real time (--realtime {pace:g})"


def link_mismatch(pace: float | None, message, side: str) -> str | None:
    """None when the other side's hello runs the link as this side does (`pace`: the real-time
    pace, None the lockstep), or states no mode; else one line naming both, as `side`
    ("station" or "controller") says it."""
    stated, theirs = link_pace(message)
    if not stated or theirs == pace:
        return None
    if side == "station":
        said = f"the controller runs {_mode(theirs)}, this station serves {_mode(pace)}"
    else:
        said = f"the station serves {_mode(theirs)}, this controller runs {_mode(pace)}"
    return f"{said}: start both with the same --realtime option, or neither with it"


def check_hello(identity: ScenarioIdentity | None, pace: float | None, message) -> None:
    """The station's side of step 0: ScenarioMismatch, naming what differs, if the controller's
    hello `message` runs another scenario than `identity` (None: any) or runs the link
    otherwise than `pace` (None: the lockstep)."""
    theirs = their_identity(message)
    problem = None
    if identity is not None and theirs is not None:
        problem = mismatch(identity, theirs, "station")
    problem = problem or link_mismatch(pace, message, "station")
    if problem is not None:
        raise ScenarioMismatch(problem)


def no_station(url: str, missing: list[str], limit: float, realtime: bool = False) -> str:
    """The line of a controller that no station answered within `limit` s."""
    flag = " --realtime" if realtime else ""
    return (
        f"no cell station answered on {url} within {limit:g} s (nothing on "
        f"{', '.join(missing)}): start one with `hrc-drake station --scenario S{flag} "
        f"--lcm {shlex.quote(url)}`"
    )


def their_identity(message) -> ScenarioIdentity | None:
    """The identity in the other side's hello; StationLinkError if it is not one."""
    try:
        return ScenarioIdentity.from_json(message.text)
    except (ValueError, TypeError) as err:
        raise StationLinkError(
            f"the other side's hello is not a scenario identity ({err}); both sides must run "
            "the same hrc_drake version"
        ) from None


@dataclass(frozen=True)
class LockstepTimeouts:
    """Wall-clock limits of the lockstep [s]: `start` for the other side's first message,
    `step` for each later one, `resend` between resending the last messages while waiting."""

    start: float = 60.0
    step: float = 30.0
    resend: float = 0.5


def exchange_period(scenario: Scenario) -> float:
    """The lockstep's exchange period: the plant's time step. The controller's period must be
    a whole number of them, exactly in floating point, so that every update of either side
    falls on an exchange; ScenarioError naming the keys otherwise."""
    step, period = plant_step(scenario), scenario.run.period
    count = round(period / step)
    if count < 1 or count * step != period:
        raise ScenarioError(
            f"run.period {period} s is not a whole number of plant_config.time_step {step} s: the "
            "station over LCM exchanges at every plant step; choose run.period = n × time_step"
        )
    return step


class Inbox:
    """The newest message of each channel with its stamp, how many came and when the newest
    came (`arrived`, `time.monotonic()`), kept by LCM handlers that never throw (a message that
    cannot be read is kept as the error it gives), and the session messages."""

    def __init__(self, lcm: DrakeLcm, channels: dict[str, StationChannel], session: str):
        self.lcm = lcm
        self.latest: dict[str, tuple[int, bytes]] = {}
        self.count: dict[str, int] = dict.fromkeys(channels, 0)
        self.arrived: dict[str, float] = {}
        self.session: list = []
        self.errors: list[str] = []
        self.on_message: Callable[[], None] | None = None
        for name, channel in channels.items():
            lcm.Subscribe(name, lambda data, c=channel, n=name: self._keep(c, n, data))
        self._session_channel = session
        lcm.Subscribe(session, self._keep_session)

    def _keep(self, channel: StationChannel, name: str, data: bytes) -> None:
        try:
            self.latest[name] = (channel.stamp_of(data), data)
            self.count[name] += 1
            self.arrived[name] = time.monotonic()
        except LcmDecodeError as err:
            self.errors.append(f"{name}: {err}")
        if self.on_message is not None:
            self.on_message()

    def _keep_session(self, data: bytes) -> None:
        try:
            self.session.append(lcmt_station_session.decode(data))
        except LcmDecodeError as err:
            self.errors.append(f"{self._session_channel}: {err}")
        if self.on_message is not None:
            self.on_message()

    def stamp(self, name: str) -> int | None:
        """The stamp of the newest message on `name` (None: none yet)."""
        entry = self.latest.get(name)
        return None if entry is None else entry[0]

    def missing(self, names: list[str], stamp: int) -> list[str]:
        """The channels of `names` whose newest message is not stamped `stamp`;
        StationLinkError if one is stamped later (the two sides are out of step)."""
        ahead = [n for n in names if n in self.latest and self.latest[n][0] > stamp]
        if ahead:
            raise StationLinkError(
                f"out of step: {', '.join(ahead)} stamped after {stamp} us; is a second "
                f"controller or station on {self.lcm.get_lcm_url()}? give each pair its own URL"
            )
        return [n for n in names if self.stamp(n) != stamp]

    def decoded(self, name: str, channel: StationChannel) -> tuple:
        """The port values of the newest message on `name`."""
        return channel.decode(channel.message.decode(self.latest[name][1]))

    def raise_errors(self, session_errors: bool = True) -> None:
        """StationLinkError for an unreadable message or (`session_errors`) an error the other
        side reported."""
        if self.errors:
            raise StationLinkError(self.errors[0])
        for message in self.session if session_errors else ():
            if message.kind == "error":
                raise StationLinkError(f"the cell station stopped: {message.text}")

    def has_session(self, kind: str) -> bool:
        """Whether a session message of `kind` came."""
        return any(m.kind == kind for m in self.session)


def publish(lcm: DrakeLcm, channel: str, message) -> bytes:
    """Publish `message` on `channel`; its bytes (to send again should a datagram be lost)."""
    data = message.encode()
    lcm.Publish(channel, data)
    return data


def greet_station(
    lcm: DrakeLcm,
    inbox: Inbox,
    identity: ScenarioIdentity | None,
    timeouts: LockstepTimeouts,
    pace: float | None = None,
) -> None:
    """Step 0 of the protocol, the controller's side (also in the real-time mode, `pace`):
    send this controller's hello until the station answers with its own (a station started
    later, or a lost datagram, needs it again); ScenarioMismatch, naming what differs, if the
    two run different scenarios or run the link differently; StationLinkError if no station
    answers within `timeouts.start`."""
    hello = session_message(0, HELLO, identity_text(identity, pace))
    limit, start = timeouts.start, time.monotonic()
    resend_at = start
    while True:
        inbox.raise_errors()
        answers = [m for m in inbox.session if m.kind == HELLO]
        if answers:
            theirs = their_identity(answers[-1])
            problem = None if identity is None else mismatch(identity, theirs, "controller")
            problem = problem or link_mismatch(pace, answers[-1], "controller")
            if problem is not None:
                raise ScenarioMismatch(problem)
            return
        now = time.monotonic()
        if now - start > limit:
            url = lcm.get_lcm_url()
            raise StationLinkError(no_station(url, [REPORT_CHANNEL], limit, pace is not None))
        if now >= resend_at:
            publish(lcm, END_CHANNEL, hello)
            resend_at = now + timeouts.resend
        wait = min(limit - (now - start), resend_at - now)
        lcm.HandleSubscriptions(max(1, int(wait * 1000)))


def request_report(lcm: DrakeLcm, inbox: Inbox, stamp: int, limit: float) -> dict:
    """Tell the station the run is over (an "end" stamped `stamp`) and return its report (a
    dict); StationLinkError if it does not answer within `limit` s."""
    publish(lcm, END_CHANNEL, session_message(stamp, "end"))
    start = time.monotonic()
    while time.monotonic() - start < limit:
        inbox.raise_errors()
        reports = [m for m in inbox.session if m.kind == "report"]
        if reports:
            return json.loads(reports[-1].text)
        lcm.HandleSubscriptions(50)
    raise StationLinkError(
        f"the cell station did not confirm the end of the run on {lcm.get_lcm_url()} within "
        f"{limit:g} s"
    )
