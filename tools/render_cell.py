"""Pictures of the cell: a PNG render for the README, and a Meshcat recording of a settling run.

    python tools/render_cell.py png [--out docs/cell.png]
    python tools/render_cell.py html --out out/settling.html [--duration 1.0]

`png` renders the whole cell (parts seated as in state 11: F3, S12, F01) headless with Drake's
VTK render engine. `html` drops the parts a few mm above their seats, simulates them settling
while recording to Meshcat, and writes the self-contained `Meshcat.StaticHtml()` page (about
2.4 MB: keep it out of git).
"""

import argparse
import dataclasses
import io
import sys
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform

from hrc_drake.atomic import atomic_write_bytes
from hrc_drake.cell.station import make_cell_station, simulate_station, station_scenario
from hrc_drake.scenario.schema import Scenario

STATE_11 = {"oval_flange_1": "F3", "square_flange": "S12", "oval_flange_2": "F01"}


def render_png(out: Path) -> Path:
    """Render the cell with the parts of state 11 seated and save it as a PNG at `out`."""
    import matplotlib.image

    scenario = Scenario()
    # The cell alone, as in the README: the operator's body would stand in front of the camera.
    scenario = dataclasses.replace(scenario, body=dataclasses.replace(scenario.body, enabled=False))
    station = make_cell_station(
        station_scenario(scenario, initial_placements=STATE_11), camera=True
    )
    context = station.create_default_context()
    image = station.diagram.GetOutputPort("sim.camera.rgb_image").Eval(context)
    rgb = np.array(image.data, copy=True)[:, :, :3]
    buffer = io.BytesIO()
    matplotlib.image.imsave(buffer, rgb, format="png")
    return atomic_write_bytes(out, buffer.getvalue())


def record_settling(out: Path, duration: float) -> Path:
    """Record the parts of state 11 settling into their seats; save the Meshcat page at `out`."""
    station = make_cell_station(Scenario(), Meshcat())
    context = station.create_default_context()
    plant_context = station.plant.GetMyContextFromRoot(context)
    for part, X in station.placement_poses(STATE_11).items():
        lift = 0.010 if part == "oval_flange_2" else 0.005
        station.plant.SetFreeBodyPose(
            plant_context, station.part_body(part), X @ RigidTransform([0.0005, -0.0005, lift])
        )
    simulate_station(station, context, duration, recording=out)
    print(f"configuration after {duration} s: {sorted(station.configuration(context).tokens())}")
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line: `png` or `html`."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    png = sub.add_parser("png", help="render docs/cell.png")
    png.add_argument("--out", type=Path, default=Path("docs/cell.png"))
    html = sub.add_parser("html", help="save a Meshcat recording of a settling run")
    html.add_argument("--out", type=Path, required=True)
    html.add_argument("--duration", type=float, default=1.0)
    args = parser.parse_args(argv)
    if args.command == "png":
        print(f"wrote {render_png(args.out)}")
    else:
        print(f"wrote {record_settling(args.out, args.duration)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
