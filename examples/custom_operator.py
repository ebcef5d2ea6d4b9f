"""Run a scenario in the cell with an operator of your own, then look at what happened.

    python examples/custom_operator.py [--assembly models/assemblies/five-slot.yaml] [--lean]

An operator is any callable `(step, state, proposal) -> task performed`. This one always mounts
the square flange first, on the highest slots it can, and follows the robot otherwise.
"""

import argparse
from pathlib import Path

from hrc_drake import LEAN, generate_states, load_scenario, load_spec, run_scenario


class SquareFirstOperator:
    """Puts the host part (the square flange) down first, as far right as it fits."""

    def __init__(self, assembly: Path | None):
        self.space = generate_states(load_spec(assembly))

    def __call__(self, step: int, state: tuple[str, ...], proposal: str) -> str:
        if state:
            return proposal
        spec = self.space.spec
        tasks = [t for t, _ in self.space.tasks(self.space.index(state))]
        hosts = [t for t in tasks if spec.part(spec.placement(t).part).is_host]
        return hosts[-1] if hosts else proposal


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--assembly", type=Path, default=None)
    parser.add_argument("--lean", action="store_true", help="0.5 s bolting holds")
    args = parser.parse_args()

    scenario = load_scenario(None, LEAN if args.lean else None)
    if args.assembly is not None:
        scenario.assembly = str(args.assembly)
    scenario.name = "square-first"
    result = run_scenario(scenario, operator=SquareFirstOperator(args.assembly))

    for task in result.tasks:
        print(
            f"step {task.step}: robot proposed {task.proposed}, operator did {task.indicated}, "
            f"the cell shows {task.observed} ({task.end_time - task.start_time:.1f} s)"
        )
    print("states:", " -> ".join(" ".join(s) or "(empty)" for s in result.states))
    print(f"terminal: {result.done}; robot collisions: {len(result.collisions)}")
    print(f"{result.sim_time:.1f} s simulated, real-time factor {result.real_time_factor:.2f}")


if __name__ == "__main__":
    main()
