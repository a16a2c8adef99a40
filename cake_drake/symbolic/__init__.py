"""Symbolic layer: PDDL in, a validated plan out.

Parsing with positions (:mod:`.pddl`), grounding and STRIPS semantics
(:mod:`.grounding`), a registry of planners (:mod:`.planners`), plan files
(:mod:`.plans`), VAL-like validation (:mod:`.validation`), diagnosis of
unsolvable problems (:mod:`.diagnose`), Blocksworld read by structure
(:mod:`.roles`: which predicate means "on", which action picks, whatever the
names) and Blocksworld helpers and generators (:mod:`.blocksworld`); text and
S-expressions read with their positions (:mod:`.sexpr`), a domain written from memory
checked against the textbook's (:mod:`.domain_check`), a plan's kernels (:mod:`.kernels`:
what each suffix needs of the world), Fast Downward as a subprocess
(:mod:`.fast_downward`) and the learned planner (:mod:`.learned`). Facts are
tuples of lower-case strings: ``("on", "a", "b")``, ``("arm-empty",)``.
"""

from cake_drake.paths import MODELS_DIR
from cake_drake.symbolic.blocksworld import (
    NAMINGS,
    Naming,
    block_names,
    blocks_problem,
    check_goal,
    check_state,
    is_blocksworld,
    problem_text,
    random_problem,
    suite_problems,
    tower_facts,
    towers,
)
from cake_drake.symbolic.diagnose import diagnose
from cake_drake.symbolic.grounding import (
    GroundOperator,
    InapplicableActionError,
    apply_action,
    check_action,
    ground_action,
)
from cake_drake.symbolic.pddl import (
    ActionSchema,
    Domain,
    Fact,
    GroundAction,
    Predicate,
    Problem,
    fact_str,
    facts_str,
    load_domain,
    load_problem,
    parse_domain,
    parse_problem,
)
from cake_drake.symbolic.planners import (
    AUTO_STAGES,
    DEFAULT_PLANNER,
    PLANNERS,
    PlannerInfo,
    planner_info,
    solve,
    solve_problem,
)
from cake_drake.symbolic.plans import Plan, format_plan, parse_plan_text, read_plan, write_plan
from cake_drake.symbolic.roles import (
    CANONICAL,
    PICK,
    PLACE,
    ActionRole,
    BlocksworldRoles,
    BlocksworldView,
    GroundRole,
    Vocabulary,
    blocksworld_roles,
    blocksworld_view,
    canonical_action,
)
from cake_drake.symbolic.validation import ValidationResult, validate_plan

#: The shipped Blocksworld domain and the five-block problem of the exercise.
BLOCKSWORLD_DOMAIN = MODELS_DIR / "pddl" / "blocksworld.pddl"
PROBLEM_5 = MODELS_DIR / "pddl" / "problem_5.pddl"

#: Blocksworld domains under other names, read by structure: IPC, typed, renamed.
VARIANTS_DIR = MODELS_DIR / "pddl" / "variants"

#: Length of the shortest plan for PROBLEM_5 (proved by A* with LM-cut).
PROBLEM_5_OPTIMAL_LENGTH = 10

__all__ = [
    "AUTO_STAGES",
    "BLOCKSWORLD_DOMAIN",
    "CANONICAL",
    "DEFAULT_PLANNER",
    "NAMINGS",
    "PICK",
    "PLACE",
    "VARIANTS_DIR",
    "ActionRole",
    "BlocksworldRoles",
    "BlocksworldView",
    "GroundRole",
    "Naming",
    "Vocabulary",
    "block_names",
    "blocksworld_roles",
    "blocksworld_view",
    "canonical_action",
    "problem_text",
    "PLANNERS",
    "PROBLEM_5",
    "PROBLEM_5_OPTIMAL_LENGTH",
    "ActionSchema",
    "Domain",
    "Fact",
    "GroundAction",
    "GroundOperator",
    "InapplicableActionError",
    "Plan",
    "PlannerInfo",
    "Predicate",
    "Problem",
    "ValidationResult",
    "apply_action",
    "blocks_problem",
    "check_action",
    "check_goal",
    "check_state",
    "diagnose",
    "fact_str",
    "facts_str",
    "format_plan",
    "ground_action",
    "is_blocksworld",
    "load_domain",
    "load_problem",
    "parse_domain",
    "parse_plan_text",
    "parse_problem",
    "planner_info",
    "random_problem",
    "read_plan",
    "solve",
    "solve_problem",
    "suite_problems",
    "tower_facts",
    "towers",
    "validate_plan",
    "write_plan",
]
