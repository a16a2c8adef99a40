"""`python -m cake_drake.validate`: exit 0 valid, 1 invalid, 2 bad input (subprocesses)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, PROBLEM_5

D, P = str(BLOCKSWORLD_DOMAIN), str(PROBLEM_5)

OPTIMAL = """(unstack a b)
(put-down a)
(unstack b c)
(put-down b)
(pick-up c)
(stack c d)
(pick-up b)
(stack b c)
(pick-up a)
(stack a b)
"""


def validate(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.validate", *args],
        capture_output=True,
        text=True,
        timeout=60,
    )


def write(tmp_path, text: str | bytes, name: str = "plan.txt") -> str:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return str(p)


def test_valid_plan_exit_0(tmp_path):
    r = validate(D, P, write(tmp_path, OPTIMAL))
    assert r.returncode == 0, r.stderr
    assert "is valid: 10 steps reach the goal of problem 'problem-5'" in r.stdout


def test_fast_downward_sas_plan_is_accepted(tmp_path):
    r = validate(D, P, write(tmp_path, OPTIMAL + "; cost = 10 (unit cost)\n", "sas_plan"))
    assert r.returncode == 0, r.stderr


def test_inapplicable_step_exit_1(tmp_path):
    plan = OPTIMAL.replace("(pick-up c)\n", "")  # (stack c d) now fails: c is not held
    r = validate(D, P, write(tmp_path, plan))
    assert r.returncode == 1
    assert (
        "is invalid: step 5 of 9 (stack c d) is not applicable: unmet precondition (holding c)"
        in (r.stdout)
    )


def test_unmet_goal_exit_1(tmp_path):
    r = validate(D, P, write(tmp_path, "\n".join(OPTIMAL.splitlines()[:8])))
    assert r.returncode == 1
    assert "all 8 steps apply but the goal is not reached: unmet goal (on a b)" in r.stdout


def test_unknown_action_exit_1(tmp_path):
    r = validate(D, P, write(tmp_path, "(unstack a b)\n(throw a)\n"))
    assert r.returncode == 1
    assert "step 2 of 2: (throw a): no action 'throw' in domain 'blocksworld'" in r.stdout


def test_verbose_trace(tmp_path):
    r = validate("-v", D, P, write(tmp_path, "(unstack a b)\n(stack a c)\n"))
    assert r.returncode == 1
    assert "  1  (unstack a b)  ok\n  2  (stack a c)  FAILS\nfinal state: " in r.stdout


@pytest.mark.parametrize(
    "plan, expected",
    [
        (b"", "is empty; expected a plan file"),
        (b"\x00\x01\x02\x03", "not a text file"),
        (b"(unstack a b)\nunstack b c\n", "plan.txt:2: expected one action per line"),
        (b"(unstack a (b))\n", "plan.txt:1: expected one action per line"),
    ],
)
def test_bad_plan_files_exit_2(tmp_path, plan, expected):
    r = validate(D, P, write(tmp_path, plan))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.count("\n") == 1 and expected in r.stderr


@pytest.mark.parametrize(
    "args, expected",
    [
        ([D, P, "/no/plan.txt"], "/no/plan.txt: no such plan file"),
        ([D, "/no/p.pddl", "x"], "/no/p.pddl: no such PDDL problem file"),
        ([D, P], "the following arguments are required: PLAN"),
    ],
)
def test_bad_inputs_exit_2(args, expected):
    r = validate(*args)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.count("\n") == 1 and expected in r.stderr


def test_ipc_naming_plan(tmp_path):
    """A plan in the IPC naming for the IPC domain; the exercise's names are not its actions."""
    from cake_drake.symbolic import VARIANTS_DIR

    domain = str(VARIANTS_DIR / "blocksworld-ipc.pddl")
    text = PROBLEM_5.read_text().replace("on-table", "ontable").replace("arm-empty", "handempty")
    problem = write(tmp_path, text.replace("(:domain blocksworld)", "(:domain blocks)"), "p.pddl")
    ipc_plan = OPTIMAL.replace("pick-up", "pickup").replace("put-down", "putdown")
    r = validate(domain, problem, write(tmp_path, ipc_plan))
    assert r.returncode == 0, r.stdout + r.stderr
    assert "valid: 10 steps reach the goal" in r.stdout
    r = validate(domain, problem, write(tmp_path, OPTIMAL))
    assert r.returncode == 1
    assert "step 2 of 10: (put-down a): no action 'put-down' in domain 'blocks'" in r.stdout
