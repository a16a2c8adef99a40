"""Why a problem has no plan: Blocksworld consistency and delete-relaxed reachability."""

from __future__ import annotations

from cake_drake.errors import InputError
from cake_drake.symbolic.blocksworld import check_goal, check_state
from cake_drake.symbolic.grounding import ground_all, relaxed_reachable
from cake_drake.symbolic.pddl import Problem, fact_str
from cake_drake.symbolic.roles import blocksworld_roles


def diagnose(problem: Problem) -> list[str]:
    """Plain-word reasons the problem may be unsolvable (empty when none is found).

    For Blocksworld domains (read by structure, whatever their names) the
    initial state is checked for consistency (one support per block, ``clear``
    exactly when nothing is on a block, one of hand empty / holding) and the
    goal for contradictions, in the domain's own predicate names. In any
    domain, goal facts unreachable even with delete effects ignored are named:
    no plan can reach them.
    """
    msgs: list[str] = []
    try:
        roles = blocksworld_roles(problem.domain)
    except InputError:
        roles = None
    if roles is not None:
        v = roles.vocabulary
        blocks = roles.blocks(problem)
        msgs += [f"initial state: {m}" for m in check_state(problem.init, blocks, v)]
        msgs += [f"goal: {m}" for m in check_goal(problem.goal, v)]
    reached, _ = relaxed_reachable(problem.init, ground_all(problem))
    for g in sorted(problem.goal - reached):
        msgs.append(f"goal {fact_str(g)} is unreachable even with delete effects ignored")
    return msgs
