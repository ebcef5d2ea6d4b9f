"""`hrc-drake adversary`: minimax-Q against an operator with K mistakes, checked against the
exact min-max of the same game from every (state, mistakes left) (no Drake)."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from hrc_drake.paths import check_output_path
from hrc_drake.progress import ProgressLine
from hrc_drake.tasks.adversary import (
    NEVER,
    adversary_game,
    agreement,
    minimax_policy,
    policy_worst_case,
    solve_minimax,
    train_minimax,
)
from hrc_drake.tasks.graph import generate_states
from hrc_drake.tasks.mdp import MdpConfig, build_mdp
from hrc_drake.tasks.policy import POLICY_FILE, save_policy
from hrc_drake.tasks.solve import solve_exact
from hrc_drake.tasks.spec import load_spec

MAX_MISTAKES = 20


def mistake_budget(text: str) -> int:
    """`--mistakes K`: a whole number in 0 .. MAX_MISTAKES (the game holds K + 1 copies of the
    state space)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if not 0 <= value <= MAX_MISTAKES:
        raise argparse.ArgumentTypeError(
            f"{text}: give a whole number of mistakes from 0 to {MAX_MISTAKES}"
        )
    return value


def add_adversary_parser(add) -> None:
    """Register `adversary` with `add(name, func, help)` of `hrc_drake.cli.build_parser`."""
    p = add(
        "adversary",
        cmd_adversary,
        "minimax-Q against an operator with K mistakes, checked against the exact min-max",
    )
    p.add_argument(
        "--mistakes",
        type=mistake_budget,
        default=1,
        metavar="K",
        help="the operator's budget of misplacements per run (default 1)",
    )
    p.add_argument(
        "--out",
        default=None,
        help="policy file to write: the learned proposals with all K mistakes to come (an "
        "existing file that is not a policy needs --force)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace an existing --out file that is not a policy file",
    )


def cmd_adversary(args) -> int:
    """Train minimax-Q, solve the min-max exactly, and compare the learned policy's worst case
    with it from every augmented state; exit 1 unless the learner settled and agrees."""
    if args.out is not None:
        check_output_path(args.out, "--out", kind=POLICY_FILE, force=args.force)
    space = generate_states(load_spec(args.assembly))
    gamma = 0.95 if args.gamma is None else args.gamma
    game = adversary_game(space, args.mistakes, MdpConfig(gamma=gamma))
    with ProgressLine("minimax-Q", "round") as bar:
        # No total: the stop rule, not the cap of rounds, ends training.
        result = train_minimax(game, seed=args.seed, progress=lambda r, _, c: bar.update(r, 0, c))
    exact = solve_minimax(game)
    learned = agreement(exact, policy_worst_case(game, result.choice))
    # The expected-value policy of the MDP with --mistake-prob (the `exact` decider's, by
    # default): where it ignores the adversary, its worst case is longer.
    mdp = build_mdp(space, MdpConfig(gamma=gamma, mistake_prob=args.mistake_prob))
    effort = agreement(exact, policy_worst_case(game, solve_exact(mdp).choice))
    # What a policy file keeps: the proposals with all K mistakes to come, whatever is left.
    fixed = agreement(exact, policy_worst_case(game, result.choice[args.mistakes]))
    report = _report(args, space, game, result, exact, learned, effort, fixed)
    ok = result.converged and learned.all_equal
    if args.out is not None and result.converged:
        meta = {"seed": args.seed, "episodes": result.episodes, "rounds": result.rounds}
        save_policy(minimax_policy(game, result.choice, "minimax-q", meta), args.out)
        report["policy"] = str(args.out)
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        _print(report, learned.per_level, learned.states_per_level)
    if not result.converged:
        print(
            f"hrc-drake adversary: the learner did not settle in {result.rounds} rounds; "
            "nothing written",
            file=sys.stderr,
        )
    return 0 if ok else 1


def _report(args, space, game, result, exact, learned, effort, fixed) -> dict:
    """The command's JSON report: the learner against the exact min-max, the expected-value
    policy's worst case, and what a policy file keeps."""
    return {
        "spec": space.spec.name,
        "states": space.n_states,
        "mistakes": args.mistakes,
        "augmented_states": learned.states,
        "seed": args.seed,
        "gamma": game.gamma,
        "converged": result.converged,
        "rounds": result.rounds,
        "episodes": result.episodes,
        "steps": result.steps,
        "wall_time": round(result.wall_time, 3),
        "exact_wall_time": round(exact.wall_time, 3),
        "equal": learned.equal,
        "equal_per_mistakes_left": list(learned.per_level),
        "loops": learned.loops,
        "value_gap": float(np.max(np.abs(result.values - exact.values))),
        "worst_case_from_start": int(policy_worst_case(game, result.choice)[args.mistakes, 0]),
        "exact_worst_case_from_start": int(exact.tasks[args.mistakes, 0]),
        "minimum_effort": {
            "mistake_prob": args.mistake_prob,
            "longer": effort.longer,
            "loops": effort.loops,
        },
        "file_policy": {
            "equal_with_all_mistakes_to_come": fixed.per_level[-1],
            "equal": fixed.equal,
            "loops": fixed.loops,
        },
        "policy": None,
    }


def _print(r: dict, per_level: tuple[int, ...], per: int) -> None:
    levels = ", ".join(f"k={k}: {m}/{per}" for k, m in enumerate(per_level))
    start = r["worst_case_from_start"]
    print(
        f"{r['spec']}: {r['states']:,} states, up to {r['mistakes']} mistake(s): "
        f"{r['augmented_states']:,} non-terminal (state, mistakes left)"
    )
    status = "settled" if r["converged"] else "NOT settled"
    print(
        f"minimax-Q (seed {r['seed']}, gamma {r['gamma']}): {status} after {r['rounds']} rounds, "
        f"{r['episodes']:,} episodes, {r['steps']:,} steps, {r['wall_time']:.2f} s"
    )
    print(
        f"worst case of its policy = exact min-max ({r['exact_wall_time']:.2f} s) from "
        f"{r['equal']:,}/{r['augmented_states']:,} ({levels}); value gap {r['value_gap']:.3g}"
    )
    print(
        f"from the empty base with {r['mistakes']} mistake(s) to come: "
        f"{'never finishes' if start == NEVER else f'{start} tasks'} at worst "
        f"(exact {r['exact_worst_case_from_start']})"
    )
    m = r["minimum_effort"]
    print(
        f"minimum-effort policy (mistake prob {m['mistake_prob']}): worst case longer from "
        f"{m['longer']:,}, never finishing from {m['loops']:,} (state, mistakes left)"
    )
    f = r["file_policy"]
    print(
        f"as a policy file (the proposals with all {r['mistakes']} to come, whatever is left): "
        f"min-max with {r['mistakes']} to come from {f['equal_with_all_mistakes_to_come']:,}/"
        f"{per:,} states, with any number left from {f['equal']:,}/{r['augmented_states']:,}, "
        f"never finishing from {f['loops']:,}"
    )
    if r["policy"]:
        print(f"policy -> {r['policy']}")
