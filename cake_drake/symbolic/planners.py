"""Named planners: pyperplan searches in-process, Fast Downward as a subprocess.

:data:`PLANNERS` is the registry; :func:`solve` plans from files and
:func:`solve_problem` from a parsed :class:`Problem`. Every returned plan is
re-checked with the validator before it is handed out.

The default, ``auto``, is a portfolio (:data:`AUTO_STAGES`): A* with LM-cut
within a work budget (optimal when it finishes), then weighted A* with hFF
within a budget, then greedy best-first with hFF. Budgets count heuristic
evaluations, not seconds, so the same problem gets the same plan on every
machine; the plan records which stage produced it and why.
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from pyperplan.heuristics.lm_cut import LmCutHeuristic
from pyperplan.heuristics.relaxation import hFFHeuristic, hMaxHeuristic
from pyperplan.search.a_star import (
    astar_search,
    greedy_best_first_search,
    weighted_astar_search,
)

from cake_drake.errors import CakeDrakeError, InputError, NoPlanError
from cake_drake.symbolic import fast_downward
from cake_drake.symbolic.diagnose import diagnose
from cake_drake.symbolic.grounding import to_task
from cake_drake.symbolic.learned import PREFIX as LEARNED_PREFIX
from cake_drake.symbolic.learned import checkpoint_of, plan_learned
from cake_drake.symbolic.learned import describe as describe_learned
from cake_drake.symbolic.pddl import Problem, load_problem
from cake_drake.symbolic.plans import Plan
from cake_drake.symbolic.validation import validate_plan


@dataclass(frozen=True)
class PlannerInfo:
    """A registry entry: what the planner is and whether its plans are shortest."""

    name: str
    search: str
    heuristic: str
    optimal: bool
    # "pyperplan" (in-process), "fast-downward" (subprocess, `fd` extra), "portfolio",
    # "learned" (a network's choices rolled out, cake_drake.symbolic.learned)
    backend: str
    summary: str


#: The planners :func:`solve` knows, by name.
PLANNERS: dict[str, PlannerInfo] = {
    p.name: p
    for p in (
        PlannerInfo(
            "auto",
            "portfolio: A* (budget), then weighted A*, then greedy best-first",
            "LM-cut, then hFF",
            False,
            "portfolio",
            "the default: optimal A*+LM-cut when it finishes within its budget (~3 s), "
            "else wastar-ff, else gbfs-ff; the plan says which",
        ),
        PlannerInfo(
            "astar-lmcut",
            "A*",
            "LM-cut",
            True,
            "pyperplan",
            "optimal (fast up to ~8 blocks; 10-12 blocks may take minutes)",
        ),
        PlannerInfo(
            "astar-hmax",
            "A*",
            "hmax",
            True,
            "pyperplan",
            "optimal; weaker heuristic than LM-cut, for comparison",
        ),
        PlannerInfo(
            "wastar-ff",
            "weighted A* (w = 2) with preferred operators",
            "hFF",
            False,
            "pyperplan",
            "satisficing; shorter plans than gbfs-ff, a little slower",
        ),
        PlannerInfo(
            "gbfs-ff",
            "greedy best-first with preferred operators",
            "hFF",
            False,
            "pyperplan",
            "satisficing; fast on big problems, plans may be longer than necessary",
        ),
        PlannerInfo(
            "fd-lama-first",
            "Fast Downward lazy greedy best-first (lama-first)",
            "hFF + landmarks",
            False,
            "fast-downward",
            "satisficing; Fast Downward, needs the fd extra",
        ),
        PlannerInfo(
            "learned",
            "greedy rollout of the network's choices (no search)",
            "none: the network picks each action",
            False,
            "learned",
            "a network trained on problems of 3-6 blocks picks each action; any number of "
            "blocks (learned@DIR: another checkpoint)",
        ),
        PlannerInfo(
            "fd-seq-opt-lmcut",
            "Fast Downward A* (seq-opt-lmcut)",
            "LM-cut",
            True,
            "fast-downward",
            "optimal; Fast Downward, needs the fd extra",
        ),
    )
}

DEFAULT_PLANNER = "auto"


@dataclass(frozen=True)
class Stage:
    """One stage of the ``auto`` portfolio: a planner and its work budget (None: no budget).

    Work is counted per heuristic evaluation as the number of ground operators,
    times ``h + 1`` for LM-cut (which finds one landmark cut per unit of h,
    each a pass over the operators). Measured on Blocksworld, 5 to 16 blocks,
    flat and tall towers, full and partial goals, one unit costs 1.8-3.2 us of
    LM-cut and ~5 us of hFF (2-core Xeon): a budget in these units takes about
    the same time at any size and, unlike a clock, gives the same plan on
    every machine.
    """

    planner: str
    budget: float | None


#: The ``auto`` portfolio: ~2.5 s of A*+LM-cut, ~3 s of weighted A*, then GBFS.
AUTO_STAGES = (
    Stage("astar-lmcut", 1.0e6),
    Stage("wastar-ff", 6.0e5),
    Stage("gbfs-ff", None),
)

_FD_ALIASES = {"fd-lama-first": "lama-first", "fd-seq-opt-lmcut": "seq-opt-lmcut"}


def planner_info(name: str) -> PlannerInfo:
    """The registry entry for ``name``; :class:`InputError` listing the valid names otherwise.

    ``learned@DIR`` is the learned planner with the checkpoint in folder DIR.
    """
    if isinstance(name, str) and name.startswith(LEARNED_PREFIX):
        checkpoint_of(name)  # an empty DIR is named here
        learned = PLANNERS["learned"]
        folder = name[len(LEARNED_PREFIX) :]
        summary = f"the learned planner with the checkpoint {folder}"
        return PlannerInfo(name, learned.search, learned.heuristic, False, "learned", summary)
    try:
        return PLANNERS[name]
    except KeyError:
        raise InputError(
            f"unknown planner '{name}' (choose from: {', '.join(PLANNERS)}, "
            f"or {LEARNED_PREFIX}DIR for another learned checkpoint)"
        ) from None


class _LmCut(LmCutHeuristic):
    """pyperplan's LM-cut over our integer fact ids.

    LM-cut formats its facts with ``str()`` (which must return a ``str``) and
    looks them up again by name, so each fact also gets its string name as a key.
    The integer keys keep set iteration, and so the search, independent of
    ``PYTHONHASHSEED``.
    """

    def __init__(self, task):
        super().__init__(task)
        for key, fact in list(self.relaxed_facts.items()):
            if not isinstance(key, str):
                fact.name = str(key)
                self.relaxed_facts[fact.name] = fact


class _TimeUp(Exception):
    pass


class _BudgetUp(Exception):
    pass


class _Deadline:
    """Wraps a pyperplan heuristic: counts evaluations and their work, and stops the
    search at a deadline (:class:`_TimeUp`) or once the work exceeds ``budget``
    (:class:`_BudgetUp`); see :class:`Stage` for the unit of work.

    Every generated node is evaluated, so checking here bounds the search
    without threads or subprocesses.
    """

    def __init__(
        self,
        heuristic,
        deadline: float | None,
        budget: float | None = None,
        n_operators: int = 1,
        h_weighted: bool = False,
    ):
        self._h = heuristic
        self._deadline = deadline
        self._budget = budget
        self._ops = max(1, n_operators)
        self._h_weighted = h_weighted
        self.evaluations = 0
        self.work = 0.0

    def _tick(self) -> None:
        if self._budget is not None and self.work > self._budget:
            raise _BudgetUp
        if self._deadline is not None and time.perf_counter() > self._deadline:
            raise _TimeUp
        self.evaluations += 1

    def _count(self, h) -> None:
        finite = h if h != float("inf") else 0
        self.work += self._ops * (finite + 1 if self._h_weighted else 1)

    def __call__(self, node):
        self._tick()
        h = self._h(node)
        self._count(h)
        return h

    def calc_h_with_plan(self, node):
        self._tick()
        h, plan = self._h.calc_h_with_plan(node)
        self._count(h)
        return h, plan


@contextmanager
def _quiet_pyperplan():
    """pyperplan logs through the root logger (and would install a handler on first
    use); keep it silent for the duration of a search and leave logging as it was."""
    root = logging.getLogger()
    guard = None
    if not root.handlers:
        guard = logging.NullHandler()
        root.addHandler(guard)
    previous = logging.root.manager.disable
    logging.disable(logging.INFO)
    try:
        yield
    finally:
        logging.disable(previous)
        if guard is not None:
            root.removeHandler(guard)


def _pyperplan_search(
    name: str, task, deadline: float | None, budget: float | None = None, counter=None
) -> tuple[list | None, int]:
    """Run the search for ``name``; returns (operators or None, evaluation count).

    Raises :class:`_TimeUp` at the deadline and :class:`_BudgetUp` once the
    work exceeds ``budget`` (both searches of a preferred-operator planner
    together). ``counter``, a list, receives the :class:`_Deadline` used.
    """
    n_ops = len(task.operators)

    def wrap(heuristic, h_weighted=False):
        h = _Deadline(heuristic, deadline, budget, n_ops, h_weighted)
        if counter is not None:
            counter.append(h)
        return h

    if name == "astar-lmcut":
        h = wrap(_LmCut(task), h_weighted=True)
        return astar_search(task, h), h.evaluations
    if name == "astar-hmax":
        h = wrap(hMaxHeuristic(task))
        return astar_search(task, h), h.evaluations
    if name in ("gbfs-ff", "wastar-ff"):
        h = wrap(hFFHeuristic(task))

        def search(preferred: bool):
            if name == "gbfs-ff":
                return greedy_best_first_search(task, h, use_relaxed_plan=preferred)
            return weighted_astar_search(task, h, weight=2, use_relaxed_plan=preferred)

        ops = search(True)
        if ops is None:
            # Preferred-operator pruning can lose every plan; the plain search is complete.
            ops = search(False)
        return ops, h.evaluations
    raise AssertionError(name)


def _no_plan_message(problem: Problem, why: str) -> str:
    found = diagnose(problem)
    diagnosis = (
        "; ".join(found)
        if found
        else ("the Blocksworld checks and the delete relaxation find no inconsistency")
    )
    return f"no plan exists for problem '{problem.name}': {why}; diagnosis: {diagnosis}"


def _gave_up_message(problem: Problem, planner: str, time_limit: float, detail: str) -> str:
    other = "gbfs-ff" if planner not in ("gbfs-ff", "auto") else "fd-lama-first"
    return (
        f"no plan found for problem '{problem.name}' within the {time_limit:g} s time limit: "
        f"planner {planner} gave up {detail}; this does not prove that no plan exists "
        f"(try a larger --time-limit or --planner {other})"
    )


def overran_time_limit(problem: Problem, planner: str, time_limit: float, where: str | None):
    """A planner plug-in stopped at ``time_limit``: a give-up at the limit, as a built-in
    planner's is (exit 1), said as what it was."""
    at = f" (stopped at {where})" if where else ""
    return NoPlanError(
        f"no plan found for problem '{problem.name}' within the {time_limit:g} s time limit: "
        f"planner {planner!r} overran its time limit{at}; this does not prove that no plan "
        "exists (try a larger --time-limit)"
    )


def _out_of_memory(problem: Problem, planner: str, other: str) -> NoPlanError:
    return NoPlanError(
        f"no plan found for problem '{problem.name}': planner {planner} ran out of "
        f"memory; this does not prove that no plan exists (try --planner {other})"
    )


def _fast_downward(problem: Problem, planner: str, time_limit: float | None):
    result = fast_downward.run(problem, _FD_ALIASES[planner], planner, time_limit)
    if result.status == "limit":
        raise NoPlanError(_gave_up_message(problem, planner, time_limit or 0, "at the limit"))
    if result.status == "memory":
        raise _out_of_memory(problem, planner, "fd-lama-first")
    if result.status == "incomplete":
        raise NoPlanError(
            f"no plan found for problem '{problem.name}': planner {planner} ran out of "
            "states to explore, but its search is incomplete, so this proves nothing"
        )
    if result.status == "unsolvable":
        raise NoPlanError(_no_plan_message(problem, f"{planner} proved it unsolvable"))
    return result.actions


def _search(problem: Problem, search_task, planner: str, deadline, budget=None, counter=None):
    """One pyperplan search; its actions, or :class:`NoPlanError` when it proves there
    are none. :class:`_TimeUp` / :class:`_BudgetUp` pass through."""
    try:
        with _quiet_pyperplan():
            ops, evaluations = _pyperplan_search(
                planner, search_task.task, deadline, budget, counter
            )
    except MemoryError:
        raise _out_of_memory(problem, planner, "gbfs-ff") from None
    if ops is None:
        raise NoPlanError(
            _no_plan_message(
                problem, f"{planner} searched every reachable state ({evaluations} evaluated)"
            )
        )
    return tuple(search_task.actions[op.name] for op in ops)


def _auto(problem: Problem, search_task, deadline: float | None) -> tuple[tuple, str, str]:
    """Run :data:`AUTO_STAGES` in turn: (actions, planner that found them, why that one)."""
    passed: list[str] = []
    for stage in AUTO_STAGES:
        t0 = time.perf_counter()
        counter: list[_Deadline] = []
        try:
            actions = _search(problem, search_task, stage.planner, deadline, stage.budget, counter)
        except _BudgetUp:
            evaluations = counter[0].evaluations if counter else 0
            passed.append(
                f"{stage.planner} stopped at its budget after {evaluations} evaluations "
                f"({time.perf_counter() - t0:.1f} s)"
            )
            continue
        evaluations = counter[0].evaluations if counter else 0
        if not passed:
            why = f"{stage.planner} finished within its budget ({evaluations} evaluations)"
        else:
            why = "; ".join(passed) + f"; {stage.planner} found the plan"
        return actions, stage.planner, why
    raise AssertionError("the last stage of AUTO_STAGES has no budget")


def solve_problem(
    problem: Problem, planner: str = DEFAULT_PLANNER, time_limit: float | None = None
) -> Plan:
    """Plan for a parsed problem with the named planner.

    Raises :class:`NoPlanError` when no plan exists (with a diagnosis) or when
    the time limit is reached (said differently), :class:`InputError` for an
    unknown planner, a bad time limit or a missing Fast Downward. With
    ``auto`` the plan's ``planner`` is the stage that produced it, and its
    ``selection`` says why.
    """
    info = planner_info(planner)
    if time_limit is not None and not time_limit > 0:
        raise InputError(f"time limit must be a positive number of seconds, got {time_limit!r}")
    if not problem.has_goal:
        raise InputError(f"problem '{problem.name}' has no (:goal ...): nothing to plan for")

    used, selection = planner, ""
    used_info = info
    if info.backend == "learned":
        t0 = time.perf_counter()
        actions, learned = plan_learned(problem, planner, time_limit)
        elapsed = time.perf_counter() - t0
        used_info = PlannerInfo(
            planner, info.search, describe_learned(learned),
            False, "learned", info.summary,
        )  # fmt: skip
    elif info.backend == "fast-downward":
        t0 = time.perf_counter()
        actions = _fast_downward(problem, planner, time_limit)
        elapsed = time.perf_counter() - t0
    else:
        t0 = time.perf_counter()
        deadline = None if time_limit is None else t0 + time_limit
        search_task = to_task(problem)
        if search_task.unreachable_goals:
            raise NoPlanError(
                _no_plan_message(problem, "proved before search, by the delete relaxation")
            )
        try:
            if planner == "auto":
                actions, used, selection = _auto(problem, search_task, deadline)
            else:
                actions = _search(problem, search_task, planner, deadline)
        except _TimeUp:
            raise NoPlanError(
                _gave_up_message(problem, planner, time_limit or 0, "at the limit")
            ) from None
        elapsed = time.perf_counter() - t0
        used_info = PLANNERS[used]

    plan = Plan(
        tuple(actions),
        used,
        used_info.search,
        used_info.heuristic,
        elapsed,
        used_info.optimal,
        requested=planner,
        selection=selection,
    )
    check = validate_plan(problem, plan.actions)
    if not check.ok:  # a planner bug, not a user error: say so plainly
        raise CakeDrakeError(f"planner {used} returned an invalid plan: {check.message}")
    return plan


def solve(
    domain_path: str | Path,
    problem_path: str | Path,
    planner: str = DEFAULT_PLANNER,
    time_limit: float | None = None,
) -> Plan:
    """Parse the two files and plan; see :func:`solve_problem`."""
    planner_info(planner)  # an unknown name is reported before the files are read
    return solve_problem(load_problem(domain_path, problem_path), planner, time_limit)
