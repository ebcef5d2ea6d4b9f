"""Plan one task with the motion layer and validate it (clearance, joint and speed limits).

    python examples/plan_one_task.py [--assembly PATH] [--configuration F1] [--task S23]
        [--last F1]

Prints the plan's stages and moves, then the validation report.
"""

import argparse
from pathlib import Path

from hrc_drake import load_spec
from hrc_drake.cell_models import CellDesign
from hrc_drake.motion import MotionPlanner, check_plan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--assembly", type=Path, default=None)
    parser.add_argument("--configuration", default="F1", help="tokens in place, comma-separated")
    parser.add_argument("--task", default="S23")
    parser.add_argument("--last", default=None, help="the task done last (undo needs it)")
    args = parser.parse_args()

    planner = MotionPlanner(design=CellDesign.of(load_spec(args.assembly)))
    configuration = frozenset(t for t in args.configuration.split(",") if t)
    plan = planner.plan_task(configuration, args.task, last_token=args.last)
    print(f"{plan.task}: moves {plan.instance}, {plan.duration:.2f} s in all")
    for segment in plan.segments:
        print(f"  {segment.stage.value:<9} {segment.start:6.2f} .. {segment.end:6.2f} s")
    for move in plan.motions:
        optimum = move.optimal_duration
        print(f"  move {move.name:<20} {move.duration:5.2f} s (Toppra optimum {optimum:.2f} s)")
    report = check_plan(plan, planner)
    print(
        f"valid: {report.ok}; least clearance {report.min_distance * 1000:.1f} mm "
        f"({report.closest_pair}); fastest joint at {report.max_velocity_ratio:.0%} of its "
        f"limit; tcp up to {report.max_tcp_speed:.3f} m/s"
    )
    for problem in report.problems:
        print("  problem:", problem)


if __name__ == "__main__":
    main()
