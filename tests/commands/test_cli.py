"""The one CLI module: the cake-drake console script and its subcommands."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cake_drake.cli import COMMANDS, main
from tests.helpers import ROOT


def test_help_lists_every_command(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in ("run", "gains", "sweep", "world", "plan", "validate", "saycan"):
        assert name in out and name in COMMANDS


def test_an_unknown_command_is_one_line_and_exit_2(capsys):
    assert main(["fly"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "plan" in err


def test_the_library_never_imports_the_cli():
    root = ROOT / "cake_drake"
    thin = {"run", "plan", "validate", "saycan", "sweep", "record", "evaluate", "train", "cli"}
    thin = {f"{name}.py" for name in thin} | {"__main__.py"}  # the top-level entry modules
    offenders = [
        str(p.relative_to(root))
        for p in root.rglob("*.py")
        if str(p.relative_to(root)) not in thin and p.name != "__main__.py"
        and p.relative_to(root).parts[0] != "commands"  # one module a command
        and any(word in p.read_text() for word in ("cake_drake.cli", "cake_drake.commands",
                                                   "argparse"))
    ]  # fmt: skip
    assert not offenders, offenders


def test_the_console_script_runs_a_subcommand():
    script = Path(sys.executable).parent / "cake-drake"
    if not script.exists():
        pytest.skip("the package is not installed in this interpreter's environment")
    r = subprocess.run([str(script), "plan"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "10 actions" in r.stdout


@pytest.mark.parametrize(
    "flags",
    [
        ["--planner", "--seed", "18446744073709551616"],
        ["--planner", "--seed", "-3"],
        ["--rl", "models/scenarios/learning.yaml", "--name", "stack2", "--seed", "-1"],
        ["models", "--seed", str(2**31)],
    ],
    ids=["planner-2**64", "planner-negative", "rl-negative", "policy-2**31"],
)
def test_a_training_seed_out_of_range_is_one_line_before_any_work(tmp_path, flags):
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.train", *flags, "--out", str(tmp_path / "o")],
        capture_output=True, text=True, cwd=ROOT, timeout=120,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "--seed" in r.stderr and "0 to 2147483647" in r.stderr
    assert not (tmp_path / "o").exists()


def test_train_help_gives_the_recipes_own_defaults(capsys):
    from dataclasses import fields

    from cake_drake.learning.training.planner import MAX_BLOCKS, PlannerRecipe

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    default = {f.name: f.default for f in fields(PlannerRecipe)}
    assert f"--steps, default {default['steps']};" in text
    assert f"--batch-size, default {default['batch_size']};" in text
    assert (f"(default {default['min_blocks']} {default['max_blocks']}, at most "
            f"{MAX_BLOCKS})") in text  # fmt: skip
    assert f"(default {default['min_blocks']} {default['max_blocks']})" in text  # --blocks


@pytest.mark.parametrize(
    "flags, line",
    [
        (["d", "--base", "x"], "--base without --rl: it is one of RL's settings"),
        (["--planner", "--beta", "0.5"], "--beta without --dagger: it is one of DAgger's settings"),
        (["--rl", "s.yaml", "--name", "t", "--blocks", "2", "3"],
         "--blocks without --planner: it is one of the learned planner's settings"),
        (["--rl", "s.yaml", "--name", "t", "--policy", "mlp"],
         "--policy with --rl: it is not one of RL's settings (the task's training.rl recipe "
         "has them)"),
        (["--residual", "r", "--seed", "3"],
         "--seed with --residual: it is a policy's setting; a residual is fitted by least squares"),
        (["--planner", "--weights", "w"],
         "--weights with --planner: it is a policy's setting, not the learned planner's"),
        (["d", "--dagger", "1", "--resume"],
         "--resume with --dagger: DAgger starts its folder afresh"),
    ],
    ids=["rl-flag", "dagger-flag", "planner-flag", "policy-flag-with-rl", "seed-with-residual",
         "weights-with-planner", "resume-with-dagger"],
)  # fmt: skip
def test_train_refuses_a_flag_its_mode_does_not_read_in_one_line(tmp_path, flags, line):
    from cake_drake.commands.train import main_train
    from cake_drake.errors import InputError

    with pytest.raises(InputError) as e:
        main_train([*flags, "--out", str(tmp_path / "o")])
    assert str(e.value) == line
    assert not (tmp_path / "o").exists()


def test_every_flag_of_train_is_read_by_a_mode():
    from cake_drake.commands.train import EVERY_MODE, MODES, train_parser

    names = set(vars(train_parser().parse_args(["--out", "o"])))
    assert names - EVERY_MODE - {n for m in MODES for n in m.reads} == set()
    assert [m.chooser for m in MODES][-1] is None  # the mode no flag chooses comes last
