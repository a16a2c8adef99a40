"""Triangle-table kernels on plain facts: what each plan suffix needs, and where to resume."""

from __future__ import annotations

from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    PROBLEM_5,
    apply_action,
    load_problem,
    solve_problem,
)
from cake_drake.symbolic.kernels import kernels, latest_kernel

PROBLEM = load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)
PLAN = solve_problem(PROBLEM, "astar-lmcut").actions


def states():
    s = PROBLEM.init
    yield s
    for a in PLAN:
        s = apply_action(PROBLEM, s, a)
        yield s


def test_the_first_kernel_holds_at_the_start_and_the_last_is_the_goal():
    ks = kernels(PROBLEM, PLAN)
    assert len(ks) == len(PLAN) + 1
    assert ks[0] <= PROBLEM.init and ks[-1] == PROBLEM.goal


def test_after_each_step_as_planned_the_next_kernel_holds():
    ks = kernels(PROBLEM, PLAN)
    for i, s in enumerate(states()):
        assert latest_kernel(ks, s) == i


def test_a_world_that_did_some_of_the_work_skips_ahead():
    ks = kernels(PROBLEM, PLAN)
    after = list(states())
    # Someone else put a down for us: the state after two steps, reached after one.
    assert latest_kernel(ks, after[2]) == 2


def test_a_disturbance_that_undid_a_step_repeats_it_and_a_foreign_one_has_no_kernel():
    ks = kernels(PROBLEM, PLAN)
    after = list(states())
    i = PLAN.index(next(a for a in PLAN if a.name == "stack"))  # the first stack
    undone = after[i + 1] - {("on", *PLAN[i].args)} | {("on-table", PLAN[i].args[0])}
    undone = undone - {("clear", PLAN[i].args[1])} | {("clear", PLAN[i].args[1])}
    assert latest_kernel(ks, undone) is not None and latest_kernel(ks, undone) < i + 1
    # e (the bottom of the goal tower) stacked on a: no suffix of this plan gets there.
    foreign = (PROBLEM.init - {("on-table", "e"), ("on", "d", "e")}) | {
        ("on", "e", "a"),
        ("on-table", "d"),
    }
    assert latest_kernel(ks, foreign) is None
