"""`python -m cake_drake.plan`: output, exit codes, one-line errors (run as subprocesses)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    PROBLEM_5,
    VARIANTS_DIR,
    random_problem,
    read_plan,
)
from tests.helpers import DATA

D, P = str(BLOCKSWORLD_DOMAIN), str(PROBLEM_5)
PROBLEM_TEXT = PROBLEM_5.read_text()


def plan_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.plan", *args], capture_output=True, text=True, timeout=60
    )


def assert_one_line_error(r: subprocess.CompletedProcess, code: int, *fragments: str) -> str:
    assert r.returncode == code, (r.returncode, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def test_default_is_problem_5_with_the_optimal_plan():
    r = plan_cli()
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[:10] == [
        "(unstack a b)",
        "(put-down a)",
        "(unstack b c)",
        "(put-down b)",
        "(pick-up c)",
        "(stack c d)",
        "(pick-up b)",
        "(stack b c)",
        "(pick-up a)",
        "(stack a b)",
    ]
    assert lines[10].startswith(
        "planner astar-lmcut: search A*, heuristic LM-cut, 10 actions (optimal), "
    )
    assert "10 actions is the optimum for problem_5, proved by astar-lmcut" in lines[11]
    assert "'12'" in lines[11] and "satisficing" in lines[11]


def test_satisficing_planner_says_so_and_writes_the_plan(tmp_path):
    out = tmp_path / "plan.txt"
    r = plan_cli(D, P, "--planner", "gbfs-ff", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "14 actions (satisficing)" in r.stdout
    assert "returned 14 actions, 4 more than the optimum of 10" in r.stdout
    assert len(read_plan(out)) == 14
    assert "; planner: gbfs-ff (satisficing: a shorter plan may exist)" in out.read_text()


def test_lama_note_says_what_lama_returned():
    """lama-first returns the optimum (10) on problem_5: the note must not claim 12."""
    from cake_drake.symbolic import fast_downward

    assert fast_downward.available(), "the fd extra is part of the test extra"
    r = plan_cli(D, P, "--planner", "fd-lama-first")
    assert r.returncode == 0, r.stderr
    assert "10 actions (satisficing)" in r.stdout
    note = r.stdout.splitlines()[-1]
    assert "its 10-action plan is the optimum for problem_5" in note
    assert "not what this one returned" in note


def test_generated_problem(tmp_path):
    p = tmp_path / "random.pddl"
    p.write_text(random_problem(12, 3))
    r = plan_cli(D, str(p), "--planner", "gbfs-ff")
    assert r.returncode == 0, r.stderr
    assert "(satisficing)" in r.stdout and "--planner astar-lmcut finds the shortest" in r.stdout
    assert "chosen by" not in r.stdout  # gbfs-ff was asked for: no portfolio


@pytest.mark.parametrize(
    "domain, problem, first",
    [
        ("blocksworld-ipc.pddl", "ipc_blocks_4_0.pddl", "(pickup b)"),
        ("blocksworld-ipc.pddl", "ipc_tall_12.pddl", "(unstack b10 b9)"),
        ("blocksworld-typed.pddl", "typed_5.pddl", "(unstack a b)"),
        ("blocksworld-renamed.pddl", "renamed_5.pddl", "(lift-off b a)"),
    ],
)
def test_variant_domains_plan_under_auto(tmp_path, domain, problem, first):
    out = tmp_path / "plan.txt"
    r = plan_cli(str(VARIANTS_DIR / domain), str(DATA / problem), "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == first
    assert "; chosen by auto: astar-lmcut finished within its budget (" in r.stdout
    text = out.read_text()
    assert "(optimal: no shorter plan exists)" in text and "; chosen by: auto (" in text


def test_time_limit_exit_1_and_says_gave_up(tmp_path):
    p = tmp_path / "random.pddl"
    p.write_text(random_problem(14, 1))
    r = plan_cli(D, str(p), "--planner", "astar-hmax", "--time-limit", "0.3")
    line = assert_one_line_error(r, 1, "within the 0.3 s time limit", "gave up at the limit")
    assert "does not prove that no plan exists" in line


def test_unsolvable_exit_1_with_diagnosis(tmp_path):
    p = tmp_path / "p.pddl"
    p.write_text(PROBLEM_TEXT.replace("(clear a) (clear d)", "(clear a)"))
    assert_one_line_error(
        plan_cli(D, str(p)),
        1,
        "no plan exists for problem 'problem-5'",
        "d has nothing on it but (clear d) is missing",
    )


_BAD_PROBLEMS = {
    "empty": (b"", "is empty; expected a PDDL problem file"),
    "binary": (b"\x7fELF\x02\x01\x01\x00\x00\x00", "not a text file (NUL byte at offset 7)"),
    "unbalanced": (
        PROBLEM_TEXT.replace("(on d e) (on-table e)\n", "(on d e (on-table e)\n").encode(),
        "p.pddl:13:3: (:goal ...) is nested inside (:init ...) opened at line 8",
    ),
    "unclosed": (PROBLEM_TEXT.replace("e))))", "e)))").encode(), "p.pddl:5:1: this '('"),
    "undefined-predicate-init": (
        PROBLEM_TEXT.replace("(clear d)", "(free d)").encode(),
        "p.pddl:11:16: predicate 'free' is not defined in domain 'blocksworld'",
    ),
    "undefined-predicate-goal": (
        PROBLEM_TEXT.replace("(on-table e))))", "(ontable e))))").encode(),
        "p.pddl:13:52: predicate 'ontable' is not defined",
    ),
    "undefined-object": (
        PROBLEM_TEXT.replace("(on d e) (on-table e))))", "(on d f) (on-table e))))").encode(),
        "object 'f' is not declared (declared: a, b, c, d, e)",
    ),
    "wrong-arity": (
        PROBLEM_TEXT.replace("(on-table c)", "(on-table c b)").encode(),
        "p.pddl:9:23: predicate 'on-table' takes 1 argument (on-table ?x), got 2",
    ),
    "other-domain": (
        PROBLEM_TEXT.replace("(:domain blocksworld)", "(:domain gripper)").encode(),
        "problem 'problem-5' is for domain 'gripper' but",
    ),
    "unsupported": (
        PROBLEM_TEXT.replace("(:goal (and", "(:goal (or").encode(),
        "disjunction (or ...) is not supported",
    ),
}


@pytest.mark.parametrize("case", sorted(_BAD_PROBLEMS))
def test_bad_problem_files_exit_2_one_line(tmp_path, case):
    content, expected = _BAD_PROBLEMS[case]
    p = tmp_path / "p.pddl"
    p.write_bytes(content)
    assert_one_line_error(plan_cli(D, str(p)), 2, expected)


@pytest.mark.parametrize(
    "args, expected",
    [
        (["/no/such/domain.pddl", P], "/no/such/domain.pddl: no such PDDL domain file"),
        ([D, "/no/such/problem.pddl"], "no such PDDL problem file"),
        ([P, D], "this is a problem file, expected a domain file"),
        ([D], "expected DOMAIN and PROBLEM (or neither for the defaults), got 1 file"),
        (
            ["--planner", "ff"],
            "unknown planner 'ff' (choose from: auto, astar-lmcut, astar-hmax, wastar-ff",
        ),
        (["--time-limit", "soon"], "argument --time-limit: invalid float value: 'soon'"),
        (["--time-limit", "0"], "time limit must be a positive number of seconds"),
        (["--frobnicate"], "unrecognized arguments: --frobnicate"),
        (["-o", "/no/such/dir/plan.txt"], "/no/such/dir/plan.txt: cannot write the plan"),
    ],
)
def test_bad_command_lines_exit_2_one_line(args, expected):
    assert_one_line_error(plan_cli(*args), 2, expected)


def test_help_lists_planners_and_exit_codes():
    r = plan_cli("--help")
    assert r.returncode == 0
    for name in ("astar-lmcut", "astar-hmax", "gbfs-ff", "fd-lama-first", "fd-seq-opt-lmcut"):
        assert name in r.stdout
    assert "exit codes: 0 plan found; 1 no plan" in r.stdout
    assert "optimal plan for problem_5 has 10 actions" in r.stdout
