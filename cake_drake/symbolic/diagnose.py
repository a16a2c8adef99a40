"""Why a problem has no plan: Blocksworld consistency and delete-relaxed reachability."""

from __future__ import annotations

from cake_drake.symbolic.blocksworld import check_goal, check_state, is_blocksworld
from cake_drake.symbolic.grounding import ground_all, relaxed_reachable
from cake_drake.symbolic.pddl import Problem, fact_str


def diagnose(problem: Problem) -> list[str]:
    """Plain-word reasons the problem may be unsolvable (empty when none is found).

    For Blocksworld-shaped domains the initial state is checked for
    consistency (one support per block, ``clear`` exactly when nothing is on a
    block, one of ``arm-empty`` / ``holding``) and the goal for contradictions.
    In any domain, goal facts unreachable even with delete effects ignored are
    named: no plan can reach them.
    """
    msgs: list[str] = []
    if is_blocksworld(problem.domain):
        msgs += [f"initial state: {m}" for m in check_state(problem.init, problem.object_types)]
        msgs += [f"goal: {m}" for m in check_goal(problem.goal)]
    reached, _ = relaxed_reachable(problem.init, ground_all(problem))
    for g in sorted(problem.goal - reached):
        msgs.append(f"goal {fact_str(g)} is unreachable even with delete effects ignored")
    return msgs
