"""Ground actions, apply them to states, and build pyperplan search tasks.

States are frozensets of facts (tuples of strings). :func:`apply_action` is the
one place an action's STRIPS semantics live: the validator, the diagnosis and
the language-plan tool all use it. :func:`to_task` hands pyperplan a task whose
facts are small integers and whose operators are sorted by name, so that every
search is the same whatever ``PYTHONHASHSEED`` is.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable
from dataclasses import dataclass

from pyperplan.task import Operator, Task

from cake_drake.errors import EXIT_NO_PLAN, CakeDrakeError, PddlError
from cake_drake.symbolic.pddl import Fact, GroundAction, Problem, facts_str


class InapplicableActionError(CakeDrakeError):
    """An action whose preconditions do not hold in the state it is applied to."""

    exit_code = EXIT_NO_PLAN

    def __init__(self, action: GroundAction, unmet: Iterable[Fact]):
        self.action = action
        self.unmet = tuple(sorted(unmet))
        super().__init__(f"{action}: precondition not met: {facts_str(self.unmet)}")


@dataclass(frozen=True)
class GroundOperator:
    """A ground action with its precondition, add and delete lists."""

    action: GroundAction
    pre: frozenset[Fact]
    add: frozenset[Fact]
    delete: frozenset[Fact]

    def applicable(self, state: frozenset[Fact]) -> bool:
        return self.pre <= state

    def apply(self, state: frozenset[Fact]) -> frozenset[Fact]:
        """Delete, then add (an atom both deleted and added stays true)."""
        return (state - self.delete) | self.add


def _bind(fact: Fact, binding: dict[str, str]) -> Fact:
    return tuple(binding.get(x, x) for x in fact)


def check_action(problem: Problem, action: GroundAction) -> str | None:
    """Why ``action`` is not a ground instance of the domain, or None when it is."""
    domain = problem.domain
    schema = domain.actions.get(action.name)
    if schema is None:
        return (
            f"{action}: no action '{action.name}' in domain '{domain.name}' "
            f"(actions: {', '.join(sorted(domain.actions))})"
        )
    if len(action.args) != schema.arity:
        return (
            f"{action}: action '{schema.name}' takes {schema.arity} argument"
            f"{'s' * (schema.arity != 1)} {schema.signature()}, got {len(action.args)}"
        )
    for arg, (var, t) in zip(action.args, schema.params, strict=True):
        if arg not in problem.object_types:
            return f"{action}: object '{arg}' is not declared in problem '{problem.name}'"
        if not domain.is_subtype(problem.object_types[arg], t):
            return (
                f"{action}: '{arg}' has type '{problem.object_types[arg]}' but {var} of "
                f"{schema.signature()} needs type '{t}'"
            )
    return None


def ground_action(problem: Problem, action: GroundAction) -> GroundOperator:
    """Instantiate ``action``'s schema; raises :class:`PddlError` if it does not fit."""
    why = check_action(problem, action)
    if why is not None:
        raise PddlError(why)
    schema = problem.domain.actions[action.name]
    binding = {var: arg for (var, _), arg in zip(schema.params, action.args, strict=True)}
    return GroundOperator(
        action,
        frozenset(_bind(f, binding) for f in schema.pre),
        frozenset(_bind(f, binding) for f in schema.add),
        frozenset(_bind(f, binding) for f in schema.delete),
    )


def apply_action(problem: Problem, state: Iterable[Fact], action: GroundAction) -> frozenset[Fact]:
    """The state after ``action``; raises :class:`InapplicableActionError` naming unmet facts."""
    state = frozenset(state)
    op = ground_action(problem, action)
    if not op.applicable(state):
        raise InapplicableActionError(action, op.pre - state)
    return op.apply(state)


def ground_all(problem: Problem) -> list[GroundOperator]:
    """Every ground operator whose static preconditions hold, sorted by name.

    Static preconditions (predicates no action changes) are checked against
    ``:init`` here and kept in ``pre``, so operators stay valid for validation.
    """
    domain = problem.domain
    statics = domain.static_predicates
    ops = []
    for schema in sorted(domain.actions.values(), key=lambda s: s.name):
        candidates = [problem.objects_of_type(t) for _, t in schema.params]
        static_pre = [f for f in schema.pre if f[0] in statics]
        for args in itertools.product(*candidates):
            binding = {var: arg for (var, _), arg in zip(schema.params, args, strict=True)}
            if any(_bind(f, binding) not in problem.init for f in static_pre):
                continue
            ops.append(
                GroundOperator(
                    GroundAction(schema.name, tuple(args)),
                    frozenset(_bind(f, binding) for f in schema.pre),
                    frozenset(_bind(f, binding) for f in schema.add),
                    frozenset(_bind(f, binding) for f in schema.delete),
                )
            )
    ops.sort(key=lambda op: str(op.action))
    return ops


def relaxed_reachable(
    init: Iterable[Fact], ops: list[GroundOperator]
) -> tuple[frozenset[Fact], list[GroundOperator]]:
    """Facts reachable when delete effects are ignored, and the operators usable on the way."""
    reached = set(init)
    waiting: dict[Fact, list[int]] = {}
    missing = []
    queue = []
    for i, op in enumerate(ops):
        unmet = [f for f in op.pre if f not in reached]
        missing.append(len(unmet))
        for f in unmet:
            waiting.setdefault(f, []).append(i)
        if not unmet:
            queue.append(i)
    usable = []
    while queue:
        i = queue.pop()
        usable.append(i)
        for f in ops[i].add:
            if f in reached:
                continue
            reached.add(f)
            for j in waiting.pop(f, ()):
                missing[j] -= 1
                if missing[j] == 0:
                    queue.append(j)
    return frozenset(reached), [ops[i] for i in sorted(usable)]


class _FactId(int):
    """A fact number for pyperplan. Its hash is the integer itself, so sets of facts
    iterate in the same order in every process (string hashes change with
    ``PYTHONHASHSEED``); ``str()`` gives a string because pyperplan's LM-cut formats
    fact names while it computes."""

    __slots__ = ()

    def __str__(self) -> str:
        return f"fact{int(self)}"

    __repr__ = __str__


@dataclass(frozen=True)
class SearchTask:
    """A pyperplan :class:`Task` plus the tables to read its answers back."""

    task: Task
    actions: dict[str, GroundAction]  # operator name -> action
    unreachable_goals: frozenset[Fact]  # goal facts not reachable even under delete relaxation


def to_task(problem: Problem) -> SearchTask:
    """Ground ``problem`` into a deterministic pyperplan task.

    Only operators reachable under delete relaxation are kept; facts are
    numbered in sorted order and static facts are dropped from the search.
    """
    reached, ops = relaxed_reachable(problem.init, ground_all(problem))
    unreachable = frozenset(problem.goal - reached)
    statics = problem.domain.static_predicates
    fluents = sorted(f for f in reached if f[0] not in statics)
    index = {f: _FactId(i) for i, f in enumerate(fluents)}

    def ints(facts: Iterable[Fact]) -> frozenset[int]:
        return frozenset(index[f] for f in facts if f in index)

    # pyperplan's LM-cut would add a string fact for operators without preconditions
    # (its hash, and so the search, would depend on PYTHONHASHSEED); give them a
    # fact of ours that always holds instead.
    always = _FactId(len(fluents))
    fluents.append(("<always>",))
    init = ints(problem.init) | {always}
    operators = [
        Operator(str(op.action), ints(op.pre) or {always}, ints(op.add), ints(op.delete))
        for op in ops
    ]
    goals = ints(g for g in problem.goal if g[0] not in statics)
    if unreachable:  # a fact no operator adds stands for them: the search cannot succeed
        goals = goals | {_FactId(len(fluents))}
        fluents.append(("<unreachable-goal>",))
    task = Task(problem.name, frozenset(index.values()) | {always, *goals}, init, goals, operators)
    return SearchTask(task, {str(op.action): op.action for op in ops}, unreachable)
