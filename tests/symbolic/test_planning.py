"""Symbolic layer: planning, plans, validation, diagnosis, Blocksworld helpers."""

from __future__ import annotations

import logging
import os
import subprocess
import sys

import pytest

from cake_drake.errors import InputError, NoPlanError, PddlError
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    DEFAULT_PLANNER,
    PLANNERS,
    PROBLEM_5,
    PROBLEM_5_OPTIMAL_LENGTH,
    GroundAction,
    InapplicableActionError,
    Plan,
    apply_action,
    blocks_problem,
    check_state,
    diagnose,
    fast_downward,
    format_plan,
    load_domain,
    load_problem,
    parse_plan_text,
    parse_problem,
    random_problem,
    read_plan,
    solve,
    solve_problem,
    towers,
    validate_plan,
    write_plan,
)

needs_fd = pytest.mark.skipif(
    not fast_downward.available(), reason="Fast Downward (the fd extra) is not installed"
)


@pytest.fixture(scope="module")
def domain():
    return load_domain(BLOCKSWORLD_DOMAIN)


@pytest.fixture(scope="module")
def problem5():
    return load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)


def A(text: str) -> GroundAction:
    name, *args = text.strip("()").split()
    return GroundAction(name, tuple(args))


def _problem(domain, init_towers, goal_towers, name="t"):
    return parse_problem(domain, blocks_problem(name, init_towers, goal_towers))


# ------------------------------------------------------------------ the shipped problem


def test_problem_5_is_the_exercise(problem5):
    assert problem5.name == "problem-5"
    assert problem5.domain_name == "blocksworld"
    assert problem5.objects == ("a", "b", "c", "d", "e")
    assert problem5.init == {
        ("on", "a", "b"),
        ("on", "b", "c"),
        ("on-table", "c"),
        ("on", "d", "e"),
        ("on-table", "e"),
        ("clear", "a"),
        ("clear", "d"),
        ("arm-empty",),
    }
    assert towers(problem5.goal) == [["e", "d", "c", "b", "a"]]
    assert towers(problem5.init) == [["c", "b", "a"], ["e", "d"]]
    assert check_state(problem5.init, problem5.objects) == []


@pytest.mark.parametrize("planner", ["astar-lmcut", "astar-hmax"])
def test_optimal_planners_find_the_10_action_plan(planner):
    # The exercise says "12"; the shortest plan has 10 actions. A planner that
    # returned 12 here would not be optimal.
    plan = solve(BLOCKSWORLD_DOMAIN, PROBLEM_5, planner)
    assert plan.length == PROBLEM_5_OPTIMAL_LENGTH == 10
    assert plan.optimal and plan.planner == planner
    assert validate_plan(load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5), plan.actions).ok


def test_no_9_action_plan_exists(problem5, domain):
    """10 is optimal: with the goal's five on-facts, every block but e must move (c needs
    d clear first), and a bounded breadth-first check finds nothing shorter."""
    frontier = {problem5.init}
    seen = set(frontier)
    from cake_drake.symbolic.grounding import ground_all

    ops = ground_all(problem5)
    for _ in range(9):
        nxt = set()
        for s in frontier:
            for op in ops:
                if op.applicable(s):
                    t = op.apply(s)
                    assert not problem5.goal <= t
                    if t not in seen:
                        seen.add(t)
                        nxt.add(t)
        frontier = nxt


def test_gbfs_ff_is_satisficing_on_problem_5():
    plan = solve(BLOCKSWORLD_DOMAIN, PROBLEM_5, "gbfs-ff")
    assert plan.length == 14 and not plan.optimal
    assert "14 actions (satisficing)" in plan.note()


def test_plan_note_names_planner_search_heuristic():
    plan = solve(BLOCKSWORLD_DOMAIN, PROBLEM_5, "astar-lmcut")
    note = plan.note()
    assert note.startswith(
        "planner astar-lmcut: search A*, heuristic LM-cut, 10 actions (optimal), "
    )
    assert note.endswith(" ms")


def test_default_auto_gets_the_optimal_10_and_says_who_found_it():
    plan = solve(BLOCKSWORLD_DOMAIN, PROBLEM_5)
    assert plan.requested == "auto" and plan.planner == "astar-lmcut"
    assert plan.optimal and plan.length == PROBLEM_5_OPTIMAL_LENGTH
    assert plan.note().endswith(
        "; chosen by auto: astar-lmcut finished within its budget (59 evaluations)"
    )
    text = format_plan(plan)
    assert "; planner: astar-lmcut (optimal: no shorter plan exists)" in text
    assert "; chosen by: auto (astar-lmcut finished within its budget" in text


def test_pyperplan_logging_is_silenced_and_logging_left_as_found(caplog):
    root = logging.getLogger()
    handlers = list(root.handlers)
    caplog.set_level(logging.DEBUG)
    for planner in ("astar-lmcut", "gbfs-ff"):
        solve(BLOCKSWORLD_DOMAIN, PROBLEM_5, planner)
    assert [r.getMessage() for r in caplog.records] == []
    assert root.handlers == handlers and logging.root.manager.disable == logging.NOTSET


def test_unknown_planner_lists_choices():
    with pytest.raises(
        InputError,
        match="unknown planner 'fast'.*auto, astar-lmcut, astar-hmax, wastar-ff, gbfs-ff",
    ):
        solve(BLOCKSWORLD_DOMAIN, PROBLEM_5, "fast")


@pytest.mark.parametrize("limit", [0, -1.0, float("nan")])
def test_bad_time_limit(problem5, limit):
    with pytest.raises(InputError, match="time limit must be a positive"):
        solve_problem(problem5, time_limit=limit)


# ------------------------------------------------------------------ no plan


def test_time_limit_is_not_unsolvable(domain):
    hard = parse_problem(domain, random_problem(14, 1))
    with pytest.raises(NoPlanError) as e:
        solve_problem(hard, "astar-hmax", time_limit=0.2)
    msg = str(e.value)
    assert "within the 0.2 s time limit" in msg
    assert "does not prove that no plan exists" in msg
    assert msg.startswith("no plan found for problem")


def test_unsolvable_by_search_is_proved_and_diagnosed(domain):
    # A goal that is a loop: each fact is reachable alone, no state holds them all.
    p = _problem(domain, [["a"], ["b"]], [])
    looped = parse_problem(
        domain, p.text.replace("(:goal (and ))", "(:goal (and (on a b) (on b a)))")
    )
    with pytest.raises(NoPlanError) as e:
        solve_problem(looped, "astar-lmcut")
    msg = str(e.value)
    assert msg.startswith("no plan exists for problem 't': astar-lmcut searched every reachable")
    assert "goal: a, b stand on each other in a loop: (on a b) (on b a)" in msg
    assert "\n" not in msg


def test_missing_clear_is_diagnosed(domain, problem5):
    broken = parse_problem(domain, problem5.text.replace("(clear a) (clear d)", "(clear a)"))
    assert "initial state: d has nothing on it but (clear d) is missing" in diagnose(broken)
    for planner in ("astar-lmcut", "gbfs-ff"):
        with pytest.raises(NoPlanError, match=r"no plan exists.*\(clear d\) is missing"):
            solve_problem(broken, planner)


def test_diagnose_names_relaxed_unreachable_goals(domain, problem5):
    broken = parse_problem(domain, problem5.text.replace("(clear a) (clear d)", "(clear a)"))
    assert "goal (on c d) is unreachable even with delete effects ignored" in diagnose(broken)
    assert diagnose(problem5) == []


def test_auto_falls_back_when_astar_reaches_its_budget(monkeypatch, problem5):
    from cake_drake.symbolic import planners

    small = (planners.Stage("astar-lmcut", 500.0), *planners.AUTO_STAGES[1:])
    monkeypatch.setattr(planners, "AUTO_STAGES", small)
    plan = solve_problem(problem5)
    assert plan.planner == "wastar-ff" and plan.requested == "auto" and not plan.optimal
    assert plan.selection.startswith("astar-lmcut stopped at its budget after ")
    assert plan.selection.endswith("; wastar-ff found the plan")
    assert validate_plan(problem5, plan.actions).ok
    text = format_plan(plan)
    assert "; planner: wastar-ff (satisficing: a shorter plan may exist)" in text
    assert "; chosen by: auto (astar-lmcut stopped at its budget after " in text

    last = (planners.Stage("astar-lmcut", 500.0), planners.Stage("wastar-ff", 500.0))
    monkeypatch.setattr(planners, "AUTO_STAGES", (*last, planners.Stage("gbfs-ff", None)))
    plan = solve_problem(problem5)
    assert plan.planner == "gbfs-ff" and plan.length == 14
    assert "wastar-ff stopped at its budget after " in plan.selection


def test_auto_is_deterministic_and_proves_unsolvable(domain, problem5):
    """Budgets count work, not seconds: the same problem gets the same plan."""
    p = parse_problem(domain, random_problem(9, 3))
    first, second = solve_problem(p), solve_problem(p)
    assert first.actions == second.actions and first.planner == second.planner
    broken = parse_problem(domain, problem5.text.replace("(clear a) (clear d)", "(clear a)"))
    with pytest.raises(NoPlanError, match="no plan exists .* diagnosis: initial state: d has"):
        solve_problem(broken)


def test_auto_respects_the_time_limit(domain):
    p = parse_problem(domain, random_problem(14, 1))
    with pytest.raises(NoPlanError, match="planner auto gave up at the limit"):
        solve_problem(p, "auto", time_limit=0.05)


def test_wastar_ff_is_satisficing_and_valid(domain):
    for seed in range(3):
        p = parse_problem(domain, random_problem(7, seed))
        plan = solve_problem(p, "wastar-ff")
        assert not plan.optimal and validate_plan(p, plan.actions).ok


def test_gbfs_falls_back_to_complete_search(domain):
    # Whatever the pruning does, gbfs-ff must not call a solvable problem unsolvable.
    for seed in range(5):
        p = parse_problem(domain, random_problem(6, seed))
        assert validate_plan(p, solve_problem(p, "gbfs-ff").actions).ok


# ------------------------------------------------------------------ Blocksworld helpers


def test_check_state_names_each_inconsistency():
    facts = {
        ("on", "a", "b"),
        ("on-table", "a"),  # two supports
        ("on-table", "b"),
        ("clear", "b"),  # a is on b
        ("holding", "c"),
        ("clear", "c"),  # held and clear
        ("arm-empty",),  # and holding c
        ("on-table", "e"),
    }
    msgs = check_state(facts, "abcde")
    assert "a has 2 supports: (on a b) (on-table a)" in msgs
    assert "b has a on it but (clear b) holds" in msgs
    assert "c is held but (clear c) holds (picking a block up deletes it)" in msgs
    assert "(arm-empty) and (holding c) both hold" in msgs
    assert "a has nothing on it but (clear a) is missing" in msgs
    assert "d rests on nothing: none of (on-table d), (on d ...), (holding d) holds" in msgs
    assert "e has nothing on it but (clear e) is missing" in msgs
    assert check_state({("on-table", "a")}, "a") == [
        "a has nothing on it but (clear a) is missing",
        "the arm is neither empty nor holding a block: (arm-empty) is missing",
    ]


def test_towers_order_and_errors():
    facts = [("on-table", "z"), ("on", "y", "z"), ("on-table", "b"), ("on", "a", "b")]
    assert towers(facts + [("clear", "a"), ("arm-empty",)]) == [["b", "a"], ["z", "y"]]
    with pytest.raises(InputError, match="a, b stand on each other in a loop"):
        towers([("on", "a", "b"), ("on", "b", "a")])
    with pytest.raises(InputError, match="c has 2 blocks on it: a, b"):
        towers([("on", "a", "c"), ("on", "b", "c"), ("on-table", "c")])


def test_random_problem_is_seeded_and_solvable(domain):
    assert random_problem(8, 3) == random_problem(8, 3)
    assert random_problem(8, 3) != random_problem(8, 4)
    assert "(:objects a b c d e f g h)" in random_problem(8, 3)
    assert "b30" in random_problem(30, 0)
    for n, seed in [(1, 0), (3, 1), (6, 2), (8, 5)]:
        p = parse_problem(domain, random_problem(n, seed))
        assert check_state(p.init, p.objects) == []
        plan = solve_problem(p, "astar-lmcut")
        assert validate_plan(p, plan.actions).ok
    with pytest.raises(InputError):
        random_problem(0, 0)


def test_gbfs_ff_solves_30_blocks(domain):
    p = parse_problem(domain, random_problem(30, 0))
    plan = solve_problem(p, "gbfs-ff")
    result = validate_plan(p, plan.actions)
    assert result.ok and result.final_state >= p.goal


# ------------------------------------------------------------------ apply / validate


def test_apply_action(problem5):
    s = apply_action(problem5, problem5.init, A("(unstack a b)"))
    assert ("holding", "a") in s and ("clear", "b") in s and ("arm-empty",) not in s
    with pytest.raises(InapplicableActionError) as e:
        apply_action(problem5, s, A("(stack a c)"))
    assert e.value.unmet == (("clear", "c"),)
    assert str(e.value) == "(stack a c): precondition not met: (clear c)"
    with pytest.raises(PddlError, match="no action 'fly'"):
        apply_action(problem5, s, A("(fly a)"))
    with pytest.raises(PddlError, match="object 'q' is not declared"):
        apply_action(problem5, s, A("(put-down q)"))
    with pytest.raises(PddlError, match=r"takes 2 arguments \(stack \?x \?y\), got 1"):
        apply_action(problem5, s, A("(stack a)"))


def test_validate_names_first_failing_step(problem5):
    plan = [A("(unstack a b)"), A("(put-down a)"), A("(pick-up b)"), A("(stack b a)")]
    r = validate_plan(problem5, plan)
    assert not r.ok and r.reason == "precondition"
    assert r.failed_step == 3 and r.failed_action == A("(pick-up b)")
    assert r.unmet_preconditions == (("on-table", "b"),)
    assert r.message == "step 3 of 4 (pick-up b) is not applicable: unmet precondition (on-table b)"
    assert len(r.states) == 3 and ("on-table", "a") in r.final_state


def test_validate_names_unmet_goals(problem5):
    r = validate_plan(problem5, [A("(unstack a b)"), A("(put-down a)")])
    assert not r.ok and r.reason == "goal" and r.failed_step is None
    assert ("on", "a", "b") in r.unmet_goals and ("on-table", "e") not in r.unmet_goals
    assert r.message.startswith("all 2 steps apply but the goal is not reached: unmet goals ")


def test_validate_unknown_action_is_invalid_not_a_crash(problem5):
    r = validate_plan(problem5, [A("(unstack a b)"), A("(teleport a e)")])
    assert not r.ok and r.reason == "unknown-action" and r.failed_step == 2
    assert "no action 'teleport'" in r.message and "pick-up, put-down, stack, unstack" in r.message


# ------------------------------------------------------------------ plan files


def test_plan_file_roundtrip(tmp_path):
    plan = solve(BLOCKSWORLD_DOMAIN, PROBLEM_5)
    path = tmp_path / "plan.txt"
    write_plan(plan, path)
    text = path.read_text()
    assert "; cost = 10 (unit cost)\n" in text
    assert "; planner: astar-lmcut (optimal: no shorter plan exists)\n" in text
    assert "; search: A*\n; heuristic: LM-cut\n; time: " in text
    assert read_plan(path) == plan.actions
    assert format_plan(Plan((), "gbfs-ff", "s", "h", 0.0)).count("satisficing") == 1


def test_read_plan_accepts_pyperplan_and_fast_downward_formats(tmp_path):
    soln = tmp_path / "problem.pddl.soln"
    soln.write_text("(unstack a b)\n(put-down a)\n")
    sas = tmp_path / "sas_plan"
    sas.write_text("(UNSTACK A B)\n(put-down a)\n; cost = 2 (unit cost)\n")
    numbered = tmp_path / "val.txt"
    numbered.write_text("0: (unstack a b) [1]\n1.000: (put-down a) [1]\n")
    expected = (A("(unstack a b)"), A("(put-down a)"))
    assert read_plan(soln) == read_plan(sas) == read_plan(numbered) == expected


@pytest.mark.parametrize(
    "text, line",
    [("(unstack a b)\nunstack a b\n", 2), ("; c\n\n(stack (a) b)\n", 3), ("(a b\n", 1)],
)
def test_bad_plan_file_names_the_line(text, line):
    with pytest.raises(InputError, match=rf"^plan.txt:{line}: expected one action per line"):
        parse_plan_text(text, "plan.txt")


def test_bad_plan_files(tmp_path):
    with pytest.raises(InputError, match="no such plan file"):
        read_plan(tmp_path / "missing.txt")
    (tmp_path / "empty.txt").write_text("")
    with pytest.raises(InputError, match="is empty"):
        read_plan(tmp_path / "empty.txt")
    (tmp_path / "bin").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(InputError, match="not a text file"):
        read_plan(tmp_path / "bin")


# ------------------------------------------------------------------ determinism


_DETERMINISM_SCRIPT = """
from cake_drake.symbolic import load_domain, parse_problem, random_problem, solve_problem
d = load_domain(%r)
for n, seed, planner in [(10, 7, "gbfs-ff"), (12, 7, "gbfs-ff"), (8, 0, "astar-lmcut")]:
    plan = solve_problem(parse_problem(d, random_problem(n, seed)), planner)
    print(planner, n, " ".join(map(str, plan.actions)))
"""


def test_plans_do_not_depend_on_pythonhashseed():
    outputs = []
    for seed in ("1", "12345"):
        env = {**os.environ, "PYTHONHASHSEED": seed}
        out = subprocess.run(
            [sys.executable, "-c", _DETERMINISM_SCRIPT % str(BLOCKSWORLD_DOMAIN)],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        outputs.append(out)
    assert outputs[0] == outputs[1] and outputs[0].count("\n") == 3


# ------------------------------------------------------------------ Fast Downward


@needs_fd
@pytest.mark.parametrize("planner, optimal", [("fd-seq-opt-lmcut", True), ("fd-lama-first", False)])
def test_fast_downward(planner, optimal, problem5):
    plan = solve(BLOCKSWORLD_DOMAIN, PROBLEM_5, planner)
    assert plan.optimal is optimal and validate_plan(problem5, plan.actions).ok
    if optimal:
        assert plan.length == 10


@needs_fd
def test_fast_downward_proves_unsolvable(domain, problem5):
    broken = parse_problem(domain, problem5.text.replace("(clear a) (clear d)", "(clear a)"))
    with pytest.raises(NoPlanError, match="fd-lama-first proved it unsolvable; diagnosis: "):
        solve_problem(broken, "fd-lama-first")


def test_fast_downward_missing_names_the_extra(monkeypatch, problem5):
    monkeypatch.setattr(fast_downward, "driver_path", lambda: None)
    with pytest.raises(InputError, match=r"pip install -e '\.\[fd\]'"):
        solve_problem(problem5, "fd-lama-first")


def test_registry():
    assert list(PLANNERS)[:5] == ["auto", "astar-lmcut", "astar-hmax", "wastar-ff", "gbfs-ff"]
    assert DEFAULT_PLANNER == "auto" and not PLANNERS["auto"].optimal
    assert {p for p, i in PLANNERS.items() if i.optimal} == {
        "astar-lmcut",
        "astar-hmax",
        "fd-seq-opt-lmcut",
    }
