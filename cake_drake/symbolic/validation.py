"""VAL-like plan validation: simulate the plan, name the first step that fails."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from cake_drake.symbolic.grounding import check_action, ground_action
from cake_drake.symbolic.pddl import Fact, GroundAction, Problem, facts_str


@dataclass(frozen=True)
class ValidationResult:
    """Outcome of :func:`validate_plan`.

    ``states[0]`` is the initial state and ``states[i]`` the state after step
    ``i`` (1-based), up to the last step that could be applied. ``failed_step``
    is the 1-based index of the first step that could not be applied (None if
    every step applied); ``reason`` is one of ``"ok"``, ``"unknown-action"``
    (not an instance of the domain), ``"precondition"`` or ``"goal"``.
    """

    ok: bool
    message: str
    reason: str
    states: tuple[frozenset[Fact], ...]
    actions: tuple[GroundAction, ...]
    failed_step: int | None = None
    unmet_preconditions: tuple[Fact, ...] = ()
    unmet_goals: tuple[Fact, ...] = ()

    @property
    def final_state(self) -> frozenset[Fact]:
        """The last state reached (after the last applicable step)."""
        return self.states[-1]

    @property
    def failed_action(self) -> GroundAction | None:
        return None if self.failed_step is None else self.actions[self.failed_step - 1]


def validate_plan(
    problem: Problem, actions: Iterable[GroundAction], check_goal: bool = True
) -> ValidationResult:
    """Apply ``actions`` from the initial state and check the goal.

    Stops at the first step that is not a ground instance of the domain or
    whose preconditions do not hold, naming the unmet preconditions. With
    ``check_goal`` (and a problem that has a goal) the goal facts left unmet
    at the end are named.
    """
    actions = tuple(actions)
    state = problem.init
    states = [state]
    n = len(actions)
    for i, action in enumerate(actions, start=1):
        why = check_action(problem, action)
        if why is not None:
            return ValidationResult(
                False, f"step {i} of {n}: {why}", "unknown-action", tuple(states), actions, i
            )
        op = ground_action(problem, action)
        unmet = tuple(sorted(op.pre - state))
        if unmet:
            return ValidationResult(
                False,
                f"step {i} of {n} {action} is not applicable: unmet precondition"
                f"{'s' * (len(unmet) > 1)} {facts_str(unmet)}",
                "precondition",
                tuple(states),
                actions,
                i,
                unmet_preconditions=unmet,
            )
        state = op.apply(state)
        states.append(state)
    if check_goal and problem.has_goal:
        unmet_goals = tuple(sorted(problem.goal - state))
        if unmet_goals:
            return ValidationResult(
                False,
                f"all {n} steps apply but the goal is not reached: unmet goal"
                f"{'s' * (len(unmet_goals) > 1)} {facts_str(unmet_goals)}",
                "goal",
                tuple(states),
                actions,
                unmet_goals=unmet_goals,
            )
        msg = f"valid: {n} step{'s' * (n != 1)} reach the goal of problem '{problem.name}'"
    else:
        msg = f"executable: all {n} step{'s' * (n != 1)} apply (no goal checked)"
    return ValidationResult(True, msg, "ok", tuple(states), actions)
