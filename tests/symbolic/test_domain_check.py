"""`plan --check-domain`: a domain written from memory compared with textbook Blocksworld."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, PROBLEM_5, VARIANTS_DIR
from cake_drake.symbolic.domain_check import check_domain
from cake_drake.symbolic.grounding import apply_action
from cake_drake.symbolic.pddl import load_domain, parse_problem
from tests.helpers import DATA

MISTAKES = DATA / "mistakes"


def plan_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cake_drake.plan", *args], capture_output=True, text=True, timeout=60
    )


def three_on_table(domain):
    return parse_problem(
        domain,
        "(define (problem three) (:domain blocksworld) (:objects a b c)"
        " (:init (arm-empty) (on-table a) (on-table b) (on-table c)"
        " (clear a) (clear b) (clear c)) (:goal (and)))",
        require_goal=False,
    )


@pytest.mark.parametrize(
    "name, difference, after",
    [
        (
            "stack_keeps_clear",
            "stack does not delete (clear ?y): a block could then carry two blocks",
            {("on", "a", "b"), ("on", "c", "b")},
        ),
        (
            "pickup_without_handempty",
            "pick-up lacks the precondition (arm-empty): the arm could pick up a block "
            "while holding one",
            {("holding", "a"), ("holding", "b")},
        ),
    ],
)
def test_exploitable_mistake_is_named_with_a_plan_that_exploits_it(name, difference, after):
    path = MISTAKES / f"{name}.pddl"
    r = plan_cli("--check-domain", str(path))
    assert r.returncode == 1, (r.stdout, r.stderr)
    lines = r.stdout.splitlines()
    assert lines[0] == f"{path}: {difference}"
    assert "shortest witness" in lines[-1] and "Blocksworld forbids" in lines[-1]
    # The witness is a real plan of the faulty domain that reaches a state no table shows.
    domain = load_domain(path)
    witness = check_domain(domain).witness
    problem = three_on_table(domain)
    state = problem.init
    for action in witness.plan:
        state = apply_action(problem, state, action)
    assert after <= state


def test_lost_capability_is_named():
    path = MISTAKES / "putdown_not_clear.pddl"
    r = plan_cli("--check-domain", str(path))
    assert r.returncode == 1
    assert "put-down does not add (clear ?x): a block put down could never be picked up" in r.stdout
    assert "(pick-up a) (put-down a): the domain cannot do (pick-up a)" in r.stdout


@pytest.mark.parametrize(
    "path",
    [BLOCKSWORLD_DOMAIN, *sorted(VARIANTS_DIR.glob("*.pddl"))],
    ids=lambda p: p.name,
)
def test_textbook_domains_in_any_naming_pass(path):
    r = plan_cli("--check-domain", str(path))
    assert r.returncode == 0, r.stdout
    assert r.stdout == f"{path}: the four actions mean textbook Blocksworld\n"


def test_unreadable_domain_is_exit_2(tmp_path):
    bad = tmp_path / "bad.pddl"
    bad.write_text("(define (domain x)")
    r = plan_cli("--check-domain", str(bad))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.splitlines()) == 1 and str(bad) in r.stderr


def test_plan_warns_and_drops_the_problem_5_claim_for_a_faulty_domain():
    path = MISTAKES / "stack_keeps_clear.pddl"
    r = plan_cli(str(path), str(PROBLEM_5))
    assert r.returncode == 0, r.stderr
    assert r.stderr.startswith(f"warning: {path}: not textbook Blocksworld: stack does not delete")
    assert "optimum for problem_5" not in r.stdout


def test_plan_of_the_textbook_domain_has_no_warning():
    r = plan_cli()
    assert r.returncode == 0 and r.stderr == ""
