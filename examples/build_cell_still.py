"""Build the physical cell for an assembly spec and save a camera still of it.

    python examples/build_cell_still.py [--assembly models/assemblies/four-slot.yaml]
        [--placements "oval_flange_1=F1,square_flange=S34"] [--out cell.png]

The plate, the tray and the parts are generated from the spec; `--placements` seats parts
(instance=token) before a short settling run, and the SlotMonitor's reading is printed.
"""

import argparse
import dataclasses
from pathlib import Path

import matplotlib.image
import numpy as np

from hrc_drake import load_scenario
from hrc_drake.cell.station import make_cell_station, simulate_station, station_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--assembly", type=Path, default=None, help="spec (default: flange)")
    parser.add_argument("--placements", default="", help="instance=token,... seated at start")
    parser.add_argument("--out", type=Path, default=Path("cell.png"))
    parser.add_argument("--settle", type=float, default=0.2, help="seconds simulated first")
    args = parser.parse_args()

    # The cell alone: the operator's body would stand in front of the camera.
    scenario = load_scenario(None, "{body: {enabled: false}}")
    if args.assembly is not None:
        scenario = dataclasses.replace(scenario, assembly=str(args.assembly))
    placements = dict(item.split("=") for item in args.placements.split(",") if item)
    scenario = station_scenario(scenario, initial_placements=placements)
    station = make_cell_station(scenario, camera=True)  # the scenario's camera, or the default
    design = station.design
    print(f"{design.spec.name}: {design.slots} slots, parts {', '.join(design.instance_names)}")

    context = station.create_default_context()
    simulate_station(station, context, args.settle)
    print("the SlotMonitor reads:", sorted(station.configuration(context).tokens()) or "empty")

    image = station.diagram.GetOutputPort("sim.camera.rgb_image").Eval(context)
    matplotlib.image.imsave(args.out, np.array(image.data, copy=True)[:, :, :3])
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
