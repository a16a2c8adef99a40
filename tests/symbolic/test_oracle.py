"""A second opinion: our parser, grounding and validator against unified-planning's.

unified-planning (a test-only dependency) reads the same PDDL files with its
own parser and simulates them with its own ``SequentialSimulator``; its
``SequentialPlanValidator`` judges plans. On the shipped problems, the variant
domains and every problem of the benchmark suite, both must agree on which
actions apply (in the initial state and along a random walk), on every state
reached, and on the verdict (and the failing step, unmet preconditions or
unmet goals) for valid plans and for mutated, invalid ones.
"""

from __future__ import annotations

import random

import pytest

from tests.helpers import DATA

up = pytest.importorskip(
    "unified_planning",
    reason="unified-planning is not installed (pip install -e '.[test]')",
)

from unified_planning.engines.plan_validator import SequentialPlanValidator  # noqa: E402
from unified_planning.engines.results import (  # noqa: E402
    FailedValidationReason,
    ValidationResultStatus,
)
from unified_planning.engines.sequential_simulator import UPSequentialSimulator  # noqa: E402
from unified_planning.environment import get_environment  # noqa: E402
from unified_planning.io import PDDLReader  # noqa: E402
from unified_planning.plans import ActionInstance, SequentialPlan  # noqa: E402

from cake_drake import MODELS_DIR  # noqa: E402
from cake_drake.symbolic import (  # noqa: E402
    BLOCKSWORLD_DOMAIN,
    PROBLEM_5,
    VARIANTS_DIR,
    GroundAction,
    Problem,
    load_domain,
    load_problem,
    parse_problem,
    solve_problem,
    suite_problems,
    validate_plan,
)
from cake_drake.symbolic.grounding import ground_all  # noqa: E402

get_environment().credits_stream = None  # unified-planning prints credits otherwise
# The kitchen domain has a constant named like its type (robot - robot): legal PDDL,
# which unified-planning refuses unless told to allow a name used twice.
get_environment().error_used_name = False
pytestmark = pytest.mark.filterwarnings("ignore:Name robot already defined:UserWarning")

PDDL = MODELS_DIR / "pddl"

SHIPPED = [
    ("problem_5", BLOCKSWORLD_DOMAIN, PROBLEM_5),
    ("kitchen_drawer", PDDL / "kitchen.pddl", PDDL / "kitchen_drawer.pddl"),
    ("kitchen_snack", PDDL / "kitchen.pddl", PDDL / "kitchen_snack.pddl"),
    ("kitchen_spill", PDDL / "kitchen.pddl", PDDL / "kitchen_spill.pddl"),
    ("ipc_blocks_4_0", VARIANTS_DIR / "blocksworld-ipc.pddl", DATA / "ipc_blocks_4_0.pddl"),
    ("ipc_tall_12", VARIANTS_DIR / "blocksworld-ipc.pddl", DATA / "ipc_tall_12.pddl"),
    ("typed_5", VARIANTS_DIR / "blocksworld-typed.pddl", DATA / "typed_5.pddl"),
    ("renamed_5", VARIANTS_DIR / "blocksworld-renamed.pddl", DATA / "renamed_5.pddl"),
]


class Pair:
    """One problem read by both implementations."""

    def __init__(self, ours: Problem, domain_text: str, problem_text: str):
        self.ours = ours
        self.theirs = PDDLReader().parse_problem_string(domain_text, problem_text)
        self.sim = UPSequentialSimulator(self.theirs)
        self.ops = ground_all(ours)

    def up_action(self, action: GroundAction) -> ActionInstance:
        t = self.theirs
        return ActionInstance(t.action(action.name), [t.object(a) for a in action.args])

    def up_applicable(self, state) -> set[GroundAction]:
        return {
            GroundAction(a.name, tuple(p.object().name for p in params))
            for a, params in self.sim.get_applicable_actions(state)
        }

    def our_applicable(self, state) -> set[GroundAction]:
        return {op.action for op in self.ops if op.applicable(state)}

    def up_facts(self, state) -> frozenset[tuple[str, ...]]:
        """Every true atom of a UP state, as our fact tuples."""
        em = self.theirs.environment.expression_manager
        facts = set()
        for fluent in self.theirs.fluents:
            domains = [list(self.theirs.objects(p.type)) for p in fluent.signature]
            combos = [[]]
            for objs in domains:
                combos = [c + [o] for c in combos for o in objs]
            for objs in combos:
                value = state.get_value(em.FluentExp(fluent, objs))
                if value.bool_constant_value():
                    facts.add((fluent.name, *(o.name for o in objs)))
        return frozenset(facts)


def _pairs():
    for name, domain, problem in SHIPPED:
        yield pytest.param(
            name, domain.read_text(), problem.read_text(), (domain, problem), id=name
        )
    for name, naming, text in suite_problems():
        yield pytest.param(name, naming.domain_file.read_text(), text, naming.domain_file, id=name)


def _load(domain_text: str, problem_text: str, source) -> Pair:
    if isinstance(source, tuple):
        ours = load_problem(*source)
    else:
        ours = parse_problem(load_domain(source), problem_text, "suite")
    return Pair(ours, domain_text, problem_text)


@pytest.mark.parametrize("name, domain_text, problem_text, source", list(_pairs()))
def test_same_applicable_actions_and_states_along_a_random_walk(
    name, domain_text, problem_text, source
):
    pair = _load(domain_text, problem_text, source)
    rng = random.Random(name)
    ours = pair.ours.init
    theirs = pair.sim.get_initial_state()
    assert pair.up_facts(theirs) == ours
    for _ in range(8):
        applicable = pair.our_applicable(ours)
        assert applicable == pair.up_applicable(theirs), name
        if not applicable:
            break
        action = rng.choice(sorted(applicable, key=str))
        ours = next(op for op in pair.ops if op.action == action).apply(ours)
        theirs = pair.sim.apply(theirs, pair.up_action(action))
        assert pair.up_facts(theirs) == ours, (name, str(action))


def _up_verdict(pair: Pair, actions) -> tuple[str, int | None]:
    """unified-planning's verdict: ("ok" | "precondition" | "goal", failing step)."""
    plan = SequentialPlan([pair.up_action(a) for a in actions])
    result = SequentialPlanValidator().validate(pair.theirs, plan)
    if result.status == ValidationResultStatus.VALID:
        return "ok", None
    if result.reason == FailedValidationReason.INAPPLICABLE_ACTION:
        return "precondition", len(result.trace)
    assert result.reason == FailedValidationReason.UNSATISFIED_GOALS
    return "goal", None


def _mutations(actions: tuple[GroundAction, ...], objects: list[str], rng: random.Random):
    """Plans that differ from ``actions`` in one way each (most are invalid)."""
    n = len(actions)
    if n == 0:
        return
    i = rng.randrange(n)
    yield actions[:i] + actions[i + 1 :]  # a step left out
    yield actions[: n - 1]  # the last step missing: goal unmet
    if n > 1:
        j = rng.randrange(n - 1)
        yield actions[:j] + (actions[j + 1], actions[j]) + actions[j + 2 :]  # two swapped
    yield actions[: i + 1] + (actions[i],) + actions[i + 1 :]  # a step repeated
    a = actions[i]
    other = rng.choice([o for o in objects if o not in a.args] or objects)
    k = rng.randrange(len(a.args)) if a.args else None
    if k is not None:
        changed = GroundAction(a.name, a.args[:k] + (other,) + a.args[k + 1 :])
        yield actions[:i] + (changed,) + actions[i + 1 :]  # another block


@pytest.mark.parametrize("name, domain_text, problem_text, source", list(_pairs()))
def test_same_verdicts_on_valid_and_mutated_plans(name, domain_text, problem_text, source):
    pair = _load(domain_text, problem_text, source)
    plan = solve_problem(pair.ours, "gbfs-ff")
    rng = random.Random(name)
    objects = sorted(o for o in pair.ours.object_types if o not in pair.ours.domain.constants)
    verdicts = set()
    for actions in (plan.actions, *_mutations(plan.actions, objects, rng)):
        ours = validate_plan(pair.ours, actions)
        if ours.reason == "unknown-action":  # a block where a location belongs
            continue
        theirs, step = _up_verdict(pair, actions)
        assert (ours.reason, ours.failed_step) == (theirs, step), (name, [str(a) for a in actions])
        if ours.reason == "precondition":
            unmet, _ = pair.sim.get_unsatisfied_conditions(
                _up_state(pair, actions[: step - 1]), pair.up_action(actions[step - 1])
            )
            assert {str(c) for c in unmet} == {_up_str(f) for f in ours.unmet_preconditions}
        if ours.reason == "goal":
            unmet_goals = pair.sim.get_unsatisfied_goals(_up_state(pair, actions))
            assert ours.unmet_goals and unmet_goals  # UP reports the goal as one conjunction
        verdicts.add(ours.reason)
    assert "ok" in verdicts and len(verdicts) > 1  # the valid plan and at least one invalid


def _up_state(pair: Pair, actions):
    state = pair.sim.get_initial_state()
    for a in actions:
        state = pair.sim.apply(state, pair.up_action(a))
    return state


def _up_str(fact: tuple[str, ...]) -> str:
    """``("on", "a", "b")`` as unified-planning prints it: ``on(a, b)``."""
    return fact[0] if len(fact) == 1 else f"{fact[0]}({', '.join(fact[1:])})"
