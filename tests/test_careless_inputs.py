"""Issue 28, item 5: every careless input gets one line naming the key or flag, and exit 2,
before any work (no planning, no simulation, no file written); output files that are not of the
kind a command writes are kept unless `--force`."""

import argparse
import json
from pathlib import Path

import pytest

from hrc_drake.cli import build_parser, main
from hrc_drake.cli import evaluate as evaluate_command
from hrc_drake.paths import check_output_path, fresh_name
from hrc_drake.resources import models_dir
from hrc_drake.scenario.load import load_scenario
from hrc_drake.scenario.schema import ScenarioError
from hrc_drake.tasks.policy import POLICY_FILE, is_policy_file, load_policy, save_policy
from hrc_drake.tasks.solve import exact_policy

FOUR_SLOT = str(models_dir() / "assemblies" / "four-slot.yaml")
FLANGE = str(models_dir() / "assemblies" / "flange.yaml")


def refused(capsys, *argv):
    """Run `hrc-drake argv` in-process; (exit status, stdout, stderr), whether the status was
    returned (a check in a command) or raised by argparse (a flag's type)."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as stop:
        code = stop.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(code, out, err, *words):
    """Exit 2, nothing on stdout, one `hrc-drake CMD: error:` line naming `words`."""
    assert code == 2, (out, err)
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("hrc-drake ") and ": error: " in err, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, (word, err)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("{motion: {tcp_speed_limit: 0}}", "motion.tcp_speed_limit"),
        ("{motion: {hold_time: .nan}}", "motion.hold_time"),
        ("{motion: {hold_time: .inf}}", "motion.hold_time"),
        ("{run: {max_sim_time: .inf}}", "run.max_sim_time"),
        ("{plant_config: {time_step: .nan}}", "plant_config.time_step"),
        ("{station: {ur3: {kp: [.nan, 1, 1, 1, 1, 1]}}}", "station.ur3.kp[0]"),
        ("{run: {max_steps: 0}}", "run.max_steps"),
        ("{safety: {slow_band: -1}}", "safety.slow_band"),
        ("{station: {rg2: {grip_tolerance: 0}}}", "station.rg2.grip_tolerance"),
        # Issue 51: speeds the UR3 cannot reach ran (50 m/s for 0.5).
        ("{motion: {tcp_speed_limit: 50}}", "motion.tcp_speed_limit"),
        ("{safety: {contact_speed: 9}}", "safety.contact_speed"),
        ("{safety: {moving_speed: 7}}", "safety.moving_speed"),
        ("{assembly: four-slott}", "assembly"),
    ],
)
def test_bad_scenario_numbers_are_one_line_naming_scenario_text(capsys, tmp_path, text, key):
    record = tmp_path / "run.html"
    argv = ["simulate", "--scenario", "row4-forces-4", "--scenario-text", text, "--record", record]
    assert_one_line(*refused(capsys, *argv), "--scenario-text", key)
    assert not record.exists()


def test_a_bad_number_in_a_scenario_file_is_blamed_on_the_file(capsys, tmp_path):
    scenario = tmp_path / "slow.yaml"
    scenario.write_text("motion: {tcp_speed_limit: 0}\n")
    code, out, err = refused(capsys, "simulate", "--scenario", scenario, "--lean")
    assert_one_line(code, out, err, f"scenario {scenario}", "motion.tcp_speed_limit")
    assert "--scenario-text" not in err
    # The text that leaves the file's mistake alone does not take the blame for it ...
    with pytest.raises(ScenarioError, match=f"scenario {scenario}: motion.tcp_speed_limit"):
        load_scenario(scenario, "{motion: {hold_time: 1.0}}")
    # ... and one that corrects it is used.
    assert load_scenario(scenario, "{motion: {tcp_speed_limit: 0.2}}").motion.tcp_speed_limit == 0.2


@pytest.mark.parametrize("where", ["bin/ls", "tmp/binary", "tmp/binary.yaml"])
def test_a_binary_scenario_file_is_one_line(capsys, tmp_path, where):
    if where == "bin/ls":
        path = Path("/bin/ls")
        if not path.is_file():
            pytest.skip("no /bin/ls here")
    else:
        path = tmp_path / where.split("/")[1]
        path.write_bytes(bytes(range(256)) * 4)
    code, out, err = refused(capsys, "simulate", "--scenario", path)
    assert_one_line(code, out, err, f"scenario {path}", "not a text file")


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "--gamma", "-1", "--out", "{tmp}/p.json"],
        ["solve", "--gamma", "nan", "--out", "{tmp}/p.json"],
        ["train", "--gamma", "5", "--out", "{tmp}/p.json"],
        ["react", "--mistake-prob", "-1"],
        ["react", "--mistake-prob", "nan"],
        ["solve", "--mistake-prob", "1", "--out", "{tmp}/p.json"],
        ["costs", "--gamma", "2", "--out", "{tmp}/c.json"],
        ["simulate", "--mistake-prob", "1.5", "--record", "{tmp}/r.html"],
        ["simulate", "--gamma", "0", "--record", "{tmp}/r.html"],
        ["evaluate", "--decider", "exact", "--operator-model", "random", "--gamma", "inf"],
    ],
)
def test_gamma_and_mistake_prob_out_of_range_are_refused_by_argparse(capsys, tmp_path, argv):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    flag = "--gamma" if "--gamma" in argv else "--mistake-prob"
    fix = "(0, 1]" if flag == "--gamma" else "[0, 1)"
    assert_one_line(*refused(capsys, *argv), f"hrc-drake {argv[0]}: error: argument {flag}", fix)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--still-time", "3"], ["--still-time", "without --still"]),
        (["--still", "{tmp}/s.png", "--still-time", "nan"], ["--still-time nan"]),
        (["--port", "7005"], ["--port 7005", "--live or --record"]),
        (["--scenario-text", "{motion: {hold_time: 1, hold_time: 5}}"], ["duplicate key"]),
        (
            ["--assembly", FOUR_SLOT, "--scenario", "row4-forces-4"],
            ["--assembly", "row4-forces-4", "'flange'"],
        ),
        (["--assembly", "/dev/null"], ["/dev/null", "character device"]),
        (["--assembly", "{tmp}"], ["is a folder"]),
    ],
)
def test_simulate_refuses_what_it_accepted_silently(capsys, tmp_path, argv, words):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert_one_line(*refused(capsys, "simulate", *argv, "--lean"), *words)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("entry", "words"),
    [
        ("{kind: grip-lost, task: 1}", ["faults[0]", "not a key", "!GripLost {task: 1}"]),
        ("{task: 1}", ["faults[0]", "untagged", "!GripLost {task: 1}"]),
        ("!Slipped {task: 1}", ["faults[0]", "unknown tag !Slipped"]),
    ],
)
def test_a_fault_without_its_tag_is_one_line_naming_the_tags(capsys, tmp_path, entry, words):
    argv = ["--scenario-text", f"{{faults: [{entry}]}}", "--record", tmp_path / "r.html"]
    assert_one_line(*refused(capsys, "simulate", *argv, "--lean"), *words, "the tags are !GripLost")
    assert list(tmp_path.iterdir()) == []


def test_duplicate_keys_in_a_scenario_file_are_refused(capsys, tmp_path):
    scenario = tmp_path / "twice.yaml"
    scenario.write_text("motion:\n  hold_time: 1\nmotion:\n  hold_time: 5\n")
    code, out, err = refused(capsys, "simulate", "--scenario", scenario)
    assert_one_line(code, out, err, str(scenario), "line 3", "duplicate key 'motion'")


def test_the_scenario_and_assembly_may_name_the_same_spec():
    from hrc_drake.cli.simulate import check_assembly_matches

    check_assembly_matches(argparse.Namespace(assembly=Path(FLANGE), scenario="row4-forces-4"))


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (None, ["/dev/null", "is a character device, not a regular file"]),
        ("", ["the file is empty"]),
        ("- a list\n", ["not a YAML mapping"]),
        (b"\xff\xfe\x00binary", ["not a text file"]),
        ("name: x\nname: y\n", ["duplicate key 'name'"]),
    ],
)
def test_assembly_files_say_what_they_are(capsys, tmp_path, content, words):
    path = Path("/dev/null")
    if content is not None:
        path = tmp_path / "spec.yaml"
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)
    assert_one_line(*refused(capsys, "states", "--assembly", path), "assembly spec", *words)


def test_evaluate_refuses_more_runs_than_the_maximum_before_any_work(capsys, monkeypatch):
    def no_work(*args):
        raise AssertionError("the cost table was asked for")

    monkeypatch.setattr(evaluate_command, "_cost_table", no_work)
    argv = ["evaluate", "--decider", "exact", "--operator-model", "random", "--runs", "10000000"]
    code, out, err = refused(capsys, *argv)
    assert_one_line(code, out, err, "--runs 10000000", "at most 1,000,000", "of memory")


def test_evaluate_refuses_a_scenario_policy_it_would_ignore(capsys, monkeypatch, tmp_path):
    """`evaluate` runs a decider; a scenario's `policy:` would be silently left out."""

    def no_work(*args):
        raise AssertionError("the cost table was asked for")

    monkeypatch.setattr(evaluate_command, "_cost_table", no_work)
    policy = tmp_path / "p.json"
    argv = ["evaluate", "--cell", "--decider", "exact", "--operator-model", "random", "--lean"]
    argv += ["--scenario-text", f"{{policy: {policy}}}"]
    code, out, err = refused(capsys, *argv)
    assert_one_line(code, out, err, "policy:", "not used by evaluate", "hrc-drake simulate")


def test_evaluate_says_how_long_a_long_evaluation_takes(capsys):
    evaluate_command._check_task_runs(100_000, 1)
    err = capsys.readouterr().err
    assert err.startswith("evaluate: 100000 runs, about ") and "of memory" in err
    evaluate_command._check_task_runs(evaluate_command.DEFAULT_RUNS, 1)
    assert capsys.readouterr().err == ""  # a short one starts at once


@pytest.mark.parametrize(
    ("argv", "name"),
    [
        (["solve", "--out", "{out}"], "notes.md"),
        (["train", "--out", "{out}"], "notes.md"),
        (["costs", "--out", "{out}"], "notes.md"),
        (["plot", "graph", "--out", "{out}"], "picture.png"),
        (["simulate", "--record", "{out}", "--lean"], "page.html"),
        (["simulate", "--still", "{out}", "--lean"], "picture.png"),
        (
            ["evaluate", "--decider", "exact", "--operator-model", "follows", "--plot", "{out}"],
            "picture.png",
        ),
    ],
)
def test_an_existing_file_of_another_kind_is_kept_without_force(capsys, tmp_path, argv, name):
    out = tmp_path / name
    out.write_text("my notes\n")
    argv = [a.format(out=out) for a in argv]
    code, stdout, err = refused(capsys, *argv)
    assert_one_line(code, stdout, err, f"{out}: exists and is not a", "--force")
    assert out.read_text() == "my notes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]


def test_force_replaces_a_file_of_another_kind(capsys, tmp_path):
    out = tmp_path / "notes.md"
    out.write_text("my notes\n")
    code, _, err = refused(capsys, "solve", "--out", out, "--force")
    assert code == 0, err
    assert is_policy_file(out)


def test_a_policy_file_is_replaced_without_force(capsys, tmp_path, flange_space):
    out = tmp_path / "policy.json"
    save_policy(exact_policy(flange_space), out)
    before = json.loads(out.read_text())
    code, _, err = refused(capsys, "solve", "--out", out, "--gamma", "0.5")
    assert code == 0, err
    after = json.loads(out.read_text())
    assert after["format"] == before["format"] and after != before
    assert load_policy(out, flange_space).method == "exact"


def test_a_corrupted_policy_file_is_still_a_policy_file(tmp_path, flange_space):
    out = tmp_path / "policy.json"
    save_policy(exact_policy(flange_space), out)
    out.write_text(out.read_text().replace('"exact"', '"edited"'))  # checksum now wrong
    assert check_output_path(out, "--out", kind=POLICY_FILE) == out


def test_policy_hints_never_advise_overwriting_a_file_that_is_not_a_policy(capsys, tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("# notes\n")
    code, out, err = refused(capsys, "policy", "--policy", readme)
    assert_one_line(code, out, err, f"policy file {readme}")
    assert f"--out {readme}" not in err
    assert f"--out {tmp_path / 'policy.json'}" in err
    (tmp_path / "policy.json").write_text("other notes\n")  # taken: the hint moves on
    code, out, err = refused(capsys, "policy", "--policy", readme)
    assert f"--out {tmp_path / 'policy-2.json'}" in err
    assert fresh_name(readme) == tmp_path / "README-2.md"


def test_a_negative_seed_is_refused_by_argparse(capsys):
    argv = ["evaluate", "--decider", "exact", "--operator-model", "follows", "--seed", "-1"]
    assert_one_line(*refused(capsys, *argv), "argument --seed", ">= 0")


def test_scenario_text_given_twice_merges_both_in_order(capsys):
    """Before: a second `--scenario-text` silently replaced the first (a camera asked for
    and a fault given in another text ran without the camera). Now each merges in turn, the
    later over the earlier, and the station's options repeat them all."""
    from hrc_drake.cli.app import build_parser
    from hrc_drake.cli.scenario_args import scenario_from_args, scenario_options

    texts = ["{motion: {hold_time: 1.5}, operator: {seed: 3}}", "{operator: {seed: 7}}"]
    argv = ["simulate", "--scenario-text", texts[0], "--scenario-text", texts[1]]
    args = build_parser().parse_args(argv)
    scenario = scenario_from_args(args)
    assert scenario.motion.hold_time == 1.5 and scenario.operator.seed == 7
    assert scenario_options(args) == ["--scenario-text", texts[0], "--scenario-text", texts[1]]
    # A mistake in either text is still one line naming the flag and the key.
    bad = [*argv, "--scenario-text", "{run: {max_steps: 0}}", "--lean"]
    assert_one_line(*refused(capsys, *bad), "--scenario-text", "run.max_steps")


# --- Issue 51: what the second new user found ---------------------------------------------------


def test_a_tcp_speed_beyond_the_ur3_names_key_value_range_and_fix(capsys):
    """Before: `motion: {tcp_speed_limit: 50}` (50 m/s) ran."""
    argv = ["simulate", "--scenario-text", "{motion: {tcp_speed_limit: 50}}", "--lean"]
    code, out, err = refused(capsys, *argv)
    assert_one_line(code, out, err, "motion.tcp_speed_limit", "50.0 m/s", "(0, 7.5] m/s", "0.25")
    # The bound itself runs, and 0 still means "separation alone" for the contact speed.
    both = "{motion: {tcp_speed_limit: 7.5}, safety: {contact_speed: 0}}"
    assert load_scenario("row1-optimal", both).motion.tcp_speed_limit == 7.5


def test_the_tcp_speed_bound_is_what_the_ur3_joints_reach():
    """`UR3_TCP_SPEED_MAX` recomputed from the published figures it cites: UR's DH parameters,
    the joints' speed limits and the RG2's TCP 0.216 m past the flange. With every joint at
    its limit, the TCP at the fastest configuration moves 7.49 m/s: the bound is above it (no
    speed the arm reaches is refused) and within 1 % of it (50 m/s is refused)."""
    import itertools

    import numpy as np

    from hrc_drake.robot_names import UR3_VELOCITY_LIMITS
    from hrc_drake.scenario.check import UR3_TCP_SPEED_MAX

    d = [0.1519, 0, 0, 0.11235, 0.08535, 0.0819]
    a = [0, -0.24365, -0.21325, 0, 0, 0]
    alpha = [np.pi / 2, 0, 0, np.pi / 2, -np.pi / 2, 0]

    def tcp_speed(q):
        frames, t = [np.eye(4)], np.eye(4)
        for i in range(6):
            ct, st, ca, sa = np.cos(q[i]), np.sin(q[i]), np.cos(alpha[i]), np.sin(alpha[i])
            t = t @ np.array(
                [[ct, -st * ca, st * sa, a[i] * ct], [st, ct * ca, -ct * sa, a[i] * st],
                 [0, sa, ca, d[i]], [0, 0, 0, 1]]
            )  # fmt: skip
            frames.append(t)
        tcp = (frames[-1] @ [0, 0, 0.216, 1])[:3]
        jac = np.array([np.cross(f[:3, 2], tcp - f[:3, 3]) for f in frames[:6]]).T
        corners = np.array(list(itertools.product([-1, 1], repeat=6))) * UR3_VELOCITY_LIMITS
        return np.linalg.norm(corners @ jac.T, axis=1).max()

    fastest = [-0.3257, 0.2978, 6.3567, -0.3256, 1.3362, -1.8935]  # found by optimisation
    assert 0.99 * UR3_TCP_SPEED_MAX < tcp_speed(fastest) <= UR3_TCP_SPEED_MAX
    rng = np.random.default_rng(0)
    assert max(tcp_speed(q) for q in rng.uniform(-np.pi, np.pi, (300, 6))) <= UR3_TCP_SPEED_MAX


def test_an_assembly_name_works_wherever_a_scenario_name_does(capsys):
    """Before: `--assembly four-slot` was "file not found" where `assembly: four-slot` works."""
    from hrc_drake.cli.app import assembly_argument
    from hrc_drake.scenario.schema import Scenario

    named = Scenario(assembly="four-slot").assembly_path
    assert assembly_argument("four-slot") == named == Path(FOUR_SLOT)
    assert assembly_argument(FOUR_SLOT) == Path(FOUR_SLOT)  # a path stays a path
    code, out, _ = refused(capsys, "states", "--assembly", "four-slot", "--json")
    assert code == 0 and len(json.loads(out)) == 44
    # Every command that takes --assembly resolves it the same way.
    (commands,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    for name, sub in commands.choices.items():
        flags = {o: a for a in sub._actions for o in a.option_strings}
        if "--assembly" in flags:
            assert flags["--assembly"].type is assembly_argument, name


def test_an_unknown_assembly_name_lists_the_known_ones(capsys):
    code, out, err = refused(capsys, "states", "--assembly", "four-slott")
    assert_one_line(code, out, err, "--assembly", "'four-slott' not found", "four-slot, ")
    code, out, err = refused(capsys, "simulate", "--scenario-text", "{assembly: four-slott}")
    assert_one_line(code, out, err, "assembly: 'four-slott' not found", "flange, four-slot")


def test_a_param_that_is_not_a_finite_number_is_refused(capsys):
    argv = ["evaluate", "--decider", "exact", "--operator-model", "slow", "--param", "growth=nan"]
    assert_one_line(*refused(capsys, *argv), "--param growth=nan", "finite number")
