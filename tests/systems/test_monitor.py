"""The closed loop: every fault kind is recovered with the monitor and fails without it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from cake_drake.pipeline import run
from cake_drake.scenario import Knock, Move, Scenario, Slip
from cake_drake.symbolic import random_problem
from tests.helpers import ROOT

#: On problem_5 (a-b-c and d-e restacked into a-b-c-d-e): c slips while carried to d;
#: d is pushed off e before either is touched; c is taken off d once it is there.
FAULTS_5 = {
    "slip": Slip(6),
    "knock": Knock("d", 1.0),
    "move": Move("c", 9.0, 0.35, -0.35),
}


def _scenario(fault, monitor: bool, problem=None) -> Scenario:
    s = Scenario(faults=[fault])
    s.reference.action_source = "monitor" if monitor else "plan"
    if problem is not None:
        s.task.problem = str(problem)
    return s


@pytest.mark.slow
@pytest.mark.parametrize("kind", FAULTS_5)
def test_each_fault_kind_is_recovered_with_the_monitor_and_not_without(kind):
    closed = run(_scenario(FAULTS_5[kind], True), write=False)
    assert closed.success, closed.message
    assert closed.execution.monitoring["events"], "the monitor saw nothing"
    facts = closed.execution.reading.facts
    assert {("on", "a", "b"), ("on", "b", "c"), ("on", "c", "d"), ("on", "d", "e")} <= facts
    opened = run(_scenario(FAULTS_5[kind], False), write=False)
    assert not opened.success, f"open loop reached the goal despite {kind}"


@pytest.mark.slow
def test_a_generated_six_block_problem_recovers_from_a_moved_cube(tmp_path):
    problem = tmp_path / "p6.pddl"
    problem.write_text(random_problem(6, seed=1))
    base = run(_scenario(Slip(1), True, problem), write=False)
    assert base.success, base.message
    # The cube the plan stacks first is moved away right after it is set down.
    first_stack = next(a for a in base.plan.actions if a.name == "stack")
    fault = Move(first_stack.args[0], 0.0, 0.45, -0.35)
    k = base.plan.actions.index(first_stack)
    fault.time = round(float(base.execution.logs.t[base.execution.logs.action == k][-1]) + 0.5, 2)
    closed = run(_scenario(fault, True, problem), write=False)
    assert closed.success, closed.message
    assert not run(_scenario(fault, False, problem), write=False).success


@pytest.mark.slow
def test_the_summary_and_the_message_tell_the_recovery(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--quiet", "--no-render", "--out", str(tmp_path),
         "--fault", "move:c@9:0.35,-0.35"],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "recovered after 1 disagreement" in r.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    event = summary["events"][0]
    assert event["kind"] in ("repeat", "replan") and "(on c d)" in event["missing"]
    assert summary["faults"] == [{"kind": "Move", "cube": "c", "time": 9.0, "x": 0.35, "y": -0.35}]
    assert len(summary["executed"]) > len(summary["plan"])


@pytest.mark.parametrize(
    "spec, words",
    [
        ("wobble:3", "unknown kind 'wobble'"),
        ("slip:x", "cannot read it"),
        ("knock:z@1", "no such cube"),
        ("knock:a@-1", "times are >= 0"),
        ("slip:99", "the plan has actions 1 to 10"),
        ("move:a@1:5,5", "not on the table"),
        ("move:a@1:0.1,0", "of the robot's base"),
    ],
)
def test_bad_fault_specs_are_refused_before_simulating(tmp_path, spec, words):
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--quiet", "--fault", spec,
         "--out", str(tmp_path / "o")],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_re_place_sets_a_loose_goal_stack_down_again_within_the_replan_budget():
    """Half-kilogram cubes, which the control plant's model lacks: computed torque sets c
    down about 13 mm off a, yet (on c a) reads true. With re_place the monitor takes it
    off to the table and the planner stacks it again, each time a replan, until the
    budget is spent; without it, nothing."""
    from cake_drake.scenario import Generate

    def heavy(re_place: bool) -> Scenario:
        s = Scenario()
        s.task.generate = Generate(blocks=3, seed=11)
        s.world.cube_mass_kg = 0.5
        s.reference.re_place, s.reference.max_replans = re_place, 2
        return s

    mended = run(heavy(True), write=False)
    events = [e for e in mended.execution.monitoring["events"] if e["kind"] == "re-place"]
    assert len(events) == 2 and mended.execution.monitoring["replans"] == 2  # the budget
    assert all(e["why"].startswith("c stands") and e["why"].endswith("mm off a") for e in events)
    # Taken off to the table, then stacked again, in that order (no skipping ahead).
    again = ("(unstack c a)", "(put-down c)", "(pick-up c)", "(stack c a)")
    assert tuple(events[0]["new_plan"]) == again
    assert mended.execution.actions[5:10] == ("(stack c a)", *again)
    plain = run(heavy(False), write=False)
    assert not plain.execution.monitoring["events"] and not plain.success
    # Every stack that left c on a measured where it landed (each time loose), and the
    # same landing in the run without re-places.
    places = mended.execution.monitoring["places"]
    assert len(places) >= 2 and {p["action"] for p in places} == {"(stack c a)"}
    assert all(p["offset_mm"] > 5.0 for p in places)
    assert plain.execution.monitoring["places"][0]["offset_mm"] > 5.0


def test_each_stack_is_measured_where_it_landed_and_a_classical_place_is_within_a_millimetre():
    result = run(Scenario(), write=False)  # problem_5: c on d, b on c, a on b
    places = result.execution.monitoring["places"]
    assert [p["action"] for p in places] == ["(stack c d)", "(stack b c)", "(stack a b)"]
    assert all(0.0 < p["offset_mm"] < 1.5 for p in places), places
