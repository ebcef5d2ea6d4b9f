"""`hrc-drake station`: the simulated station of a scenario, served over LCM to a controller
started with `hrc-drake simulate --station-lcm URL` (`hrc_drake.cell.link.remote`)."""

from __future__ import annotations

import json
import shlex
import sys

from hrc_drake.cell.link.lockstep import (
    LockstepTimeouts,
    ScenarioMismatch,
    StationLinkError,
)
from hrc_drake.cell.link.remote import check_lcm_url, serve_scenario
from hrc_drake.cell.link.scenario_identity import ScenarioIdentity
from hrc_drake.cell.scenario import lcm_url
from hrc_drake.cli.drivers import refuse_real_devices
from hrc_drake.cli.scenario_args import (
    scenario_argv,
    scenario_from_args,
    scenario_options,
    scenario_text_options,
)
from hrc_drake.paths import UsageError

EXIT_MISMATCH = 2
"""The exit status of either side of a refused station-controller pair: as for an option
refused (the two command lines must be made to agree), not 1, a link that failed."""


def controller_hint(args, url: str) -> str:
    """The command that runs the controller against a station started with `args` on `url`,
    to paste as it is into a POSIX shell or zsh (the URL's `?` quoted); with `--realtime`,
    at the same pace."""
    argv = ["hrc-drake", "simulate", *scenario_argv(args), "--station-lcm", url]
    pace = getattr(args, "realtime", None)
    if pace is not None:
        argv += ["--realtime"] if pace == 1.0 else ["--realtime", f"{pace:g}"]
    return shlex.join(argv)


def drivers_argv(args) -> list[str]:
    """The scenario options of `args` that `hrc-drake drivers` takes (`--scenario`,
    `--scenario-text`): the drivers read only the scenario's `drivers:` section."""
    argv = ["--scenario", args.scenario] if args.scenario else []
    return argv + scenario_text_options(args)


def station_command(args) -> int:
    """`hrc-drake station`: serve the scenario's simulated station over LCM until a controller
    (`hrc-drake simulate --station-lcm URL`) has run against it. Exit status 0; 1 if no
    controller came, it stopped answering or the station failed; `EXIT_MISMATCH` (2) if the
    controller runs another scenario, or runs the link otherwise (`--realtime`). A scenario
    that puts a device on real hardware is refused (UsageError, exit status 2): `hrc-drake
    drivers` serves those."""
    if not args.timeout > 0:
        raise UsageError(f"--timeout {args.timeout}: give a number of seconds > 0")
    scenario = scenario_from_args(args)
    url = check_lcm_url(args.lcm or lcm_url(scenario), "--lcm")
    refuse_real_devices(scenario, drivers_argv(args), url)
    identity = ScenarioIdentity.of(scenario, scenario_options(args))
    timeouts = LockstepTimeouts(start=args.timeout, step=args.timeout)
    print(
        f"station {scenario.name}: serving on {url}; start the controller with: "
        f"{controller_hint(args, url)}",
        file=sys.stderr,
        flush=True,
    )
    try:
        report = serve_scenario(scenario, url, timeouts, identity, pace=args.realtime)
    except ScenarioMismatch as err:
        print(f"hrc-drake station: error: {err}", file=sys.stderr)
        return EXIT_MISMATCH
    except StationLinkError as err:
        print(f"hrc-drake station: error: {err}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps({"scenario": scenario.name, "lcm": url, **report}))
    elif args.realtime is not None:
        paced = report["realtime"]
        print(
            f"station {scenario.name}: served {report['sim_time']:.2f} s in real time (pace "
            f"{paced['pace']:g}, achieved {paced['pace_achieved']:.2f}), "
            f"{report['commands']} arm commands taken"
        )
    else:
        print(
            f"station {scenario.name}: served {report['exchanges']} exchanges, "
            f"{report['sim_time']:.2f} s simulated"
        )
    return 0


__all__ = ["EXIT_MISMATCH", "controller_hint", "drivers_argv", "station_command"]
