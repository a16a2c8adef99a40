"""Triangle-table kernels: what each suffix of a plan needs of the world to reach the goal.

For a plan a_1 ... a_n and a goal G, the kernel of the suffix that starts at step i is
the goal regressed through the remaining actions::

    K_{n+1} = G,        K_i = pre(a_i) | (K_{i+1} - add(a_i))

If the world satisfies K_i, executing a_i ... a_n from it reaches the goal (STRIPS
semantics). An execution monitor reads the facts from the measured world after every
action and continues from the *latest* suffix whose kernel holds: the next step when all
went as planned, further on when the world did some of the work, an earlier step when a
disturbance undid it; when no kernel holds, the plan cannot be repaired by skipping or
repeating and the problem is planned again from the measured facts (Fikes, Hart and
Nilsson's PLANEX, 1972).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from cake_drake.symbolic.grounding import ground_action
from cake_drake.symbolic.pddl import Fact, GroundAction, Problem


def kernels(
    problem: Problem, actions: Sequence[GroundAction], goal: Iterable[Fact] | None = None
) -> list[frozenset[Fact]]:
    """``[K_0, ..., K_n]``: K_i is what the suffix ``actions[i:]`` needs (K_n is the goal)."""
    k = frozenset(problem.goal if goal is None else goal)
    out = [k]
    for action in reversed(actions):
        op = ground_action(problem, action)
        k = op.pre | (k - op.add)
        out.append(k)
    return out[::-1]


def latest_kernel(kernels_: Sequence[frozenset[Fact]], state: Iterable[Fact]) -> int | None:
    """The largest i with ``kernels_[i]`` true in ``state`` (None when none holds)."""
    state = frozenset(state)
    for i in range(len(kernels_) - 1, -1, -1):
        if kernels_[i] <= state:
            return i
    return None
