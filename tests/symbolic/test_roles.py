"""Blocksworld read by structure: every naming of the family reads the same, others are refused."""

from __future__ import annotations

import pytest

from cake_drake import MODELS_DIR
from cake_drake.errors import EXIT_BAD_INPUT, InputError, PddlError
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    CANONICAL,
    NAMINGS,
    PICK,
    PLACE,
    PROBLEM_5,
    VARIANTS_DIR,
    ActionRole,
    GroundAction,
    Vocabulary,
    blocksworld_roles,
    blocksworld_view,
    canonical_action,
    check_goal,
    check_state,
    diagnose,
    is_blocksworld,
    load_domain,
    load_problem,
    parse_domain,
    parse_problem,
    random_problem,
    solve_problem,
    towers,
    validate_plan,
)
from cake_drake.symbolic.blocksworld import random_towers
from tests.helpers import DATA

IPC = VARIANTS_DIR / "blocksworld-ipc.pddl"
TYPED = VARIANTS_DIR / "blocksworld-typed.pddl"
RENAMED = VARIANTS_DIR / "blocksworld-renamed.pddl"

STANDARD = {
    "pick-from-table": ActionRole(PICK, 0, None),
    "place-on-table": ActionRole(PLACE, 0, None),
    "place-on-block": ActionRole(PLACE, 0, 1),
    "pick-from-block": ActionRole(PICK, 0, 1),
}


def A(text: str) -> GroundAction:
    name, *args = text.strip("()").split()
    return GroundAction(name, tuple(args))


# ------------------------------------------------------------------ the family reads the same


@pytest.mark.parametrize(
    "path, vocabulary, names",
    [
        (
            BLOCKSWORLD_DOMAIN,
            CANONICAL,
            ["pick-up", "put-down", "stack", "unstack"],
        ),
        (
            IPC,
            Vocabulary("on", "ontable", "clear", "holding", "handempty"),
            ["pickup", "putdown", "stack", "unstack"],
        ),
        (
            TYPED,
            Vocabulary("on", "ontable", "clear", "holding", "handempty"),
            ["pick-up", "put-down", "stack", "unstack"],
        ),
    ],
)
def test_standard_variants(path, vocabulary, names):
    roles = blocksworld_roles(load_domain(path))
    assert roles.vocabulary == vocabulary
    assert dict(roles.actions) == dict(zip(names, STANDARD.values(), strict=True))
    assert is_blocksworld(load_domain(path))


def test_renamed_variant_with_support_first_and_a_static_precondition():
    roles = blocksworld_roles(load_domain(RENAMED))
    assert roles.vocabulary == Vocabulary("atop", "on-floor", "free", "grasped", "gripper-free")
    assert dict(roles.actions) == {
        "grasp-from-floor": ActionRole(PICK, 0, None),
        "release-on-floor": ActionRole(PLACE, 0, None),
        "place-onto": ActionRole(PLACE, 1, 0),  # (place-onto ?below ?c)
        "lift-off": ActionRole(PICK, 1, 0),
    }
    assert roles.classify(A("(place-onto b a)")).canonical() == A("(stack a b)")
    assert roles.action(PICK, "a", "b") == A("(lift-off b a)")


def test_structure_not_names_decides():
    """The exercise domain with its predicate names permuted: every name now means
    another role, and the reading follows the structure."""
    swap = {
        "on-table": "holding",
        "holding": "clear",
        "clear": "arm-empty",
        "arm-empty": "on-table",
    }
    text = BLOCKSWORLD_DOMAIN.read_text()
    for old in swap:
        text = text.replace(f"({old}", f"(<{old}>")
    for old, new in swap.items():
        text = text.replace(f"(<{old}>", f"({new}")
    roles = blocksworld_roles(parse_domain(text, "swapped.pddl"))
    assert roles.vocabulary == Vocabulary("on", "holding", "arm-empty", "clear", "on-table")
    assert dict(roles.actions) == dict(zip(["pick-up", "put-down", "stack", "unstack"],
                                           STANDARD.values(), strict=True))  # fmt: skip
    assert roles.to_canonical({("holding", "a"), ("on-table",), ("arm-empty", "b")}) == {
        ("on-table", "a"),
        ("arm-empty",),
        ("clear", "b"),
    }


# ------------------------------------------------------------------ problems in any naming


VARIANT_PROBLEMS = [
    (BLOCKSWORLD_DOMAIN, PROBLEM_5),
    (TYPED, DATA / "typed_5.pddl"),
    (RENAMED, DATA / "renamed_5.pddl"),
]


@pytest.mark.parametrize("domain, problem", VARIANT_PROBLEMS)
def test_canonical_view_is_the_same_in_every_naming(domain, problem):
    """The exercise's five blocks in three namings: one canonical initial state and goal."""
    reference = blocksworld_view(load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5))
    view = blocksworld_view(load_problem(domain, problem))
    assert view.blocks == ("a", "b", "c", "d", "e")
    assert view.init == reference.init and view.goal == reference.goal
    assert towers(view.init) == [["c", "b", "a"], ["e", "d"]]
    assert check_state(view.init, view.blocks) == []


@pytest.mark.parametrize("domain, problem", VARIANT_PROBLEMS)
def test_plans_mean_the_same_in_every_naming(domain, problem):
    """A plan in any naming, read action by action, is the exercise's optimal plan."""
    p = load_problem(domain, problem)
    roles = blocksworld_roles(p.domain)
    plan = solve_problem(p)
    assert plan.optimal and plan.length == 10
    canonical = [roles.classify(a).canonical() for a in plan.actions]
    assert validate_plan(load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5), canonical).ok
    assert [roles.action(*_meaning(a)) for a in canonical] == list(plan.actions)


def _meaning(action: GroundAction):
    r = blocksworld_roles(load_domain(BLOCKSWORLD_DOMAIN)).classify(action)
    return r.kind, r.block, r.support


def test_translation_round_trip_and_static_facts():
    p = load_problem(RENAMED, DATA / "renamed_5.pddl")
    roles = blocksworld_roles(p.domain)
    canonical = roles.to_canonical(p.init)
    assert ("cube", "a") in p.init and not any(f[0] == "cube" for f in canonical)
    assert ("on", "a", "b") in canonical and ("arm-empty",) in canonical
    assert roles.from_canonical(canonical) == {f for f in p.init if f[0] != "cube"}
    with pytest.raises(InputError, match=r"\(painted a\) is not a canonical Blocksworld fact"):
        roles.from_canonical({("painted", "a")})


def test_classify_ground_actions():
    roles = blocksworld_roles(load_domain(IPC))
    r = roles.classify(A("(unstack b3 b7)"))
    assert (r.kind, r.block, r.support) == (PICK, "b3", "b7")
    r = roles.classify(A("(putdown b1)"))
    assert (r.kind, r.block, r.support) == (PLACE, "b1", None)
    assert r.canonical() == A("(put-down b1)") == canonical_action(PLACE, "b1")
    with pytest.raises(InputError, match="no action 'pick-up' in domain 'blocks'"):
        roles.classify(A("(pick-up b1)"))


def test_ipc_problems_as_published():
    """Upper case, letters as objects, a partial goal; and a 10-high tower of 12 blocks."""
    p = load_problem(IPC, DATA / "ipc_blocks_4_0.pddl")
    view = blocksworld_view(p)
    assert view.blocks == ("a", "b", "c", "d")
    assert view.goal == {("on", "d", "c"), ("on", "c", "b"), ("on", "b", "a")}
    assert check_state(view.init, view.blocks) == [] and check_goal(view.goal) == []
    assert solve_problem(p).length == 6

    tall = blocksworld_view(load_problem(IPC, DATA / "ipc_tall_12.pddl"))
    assert tall.blocks == tuple(f"b{i}" for i in range(1, 13))  # b2 before b10
    assert towers(tall.init) == [[f"b{i}" for i in range(1, 11)], ["b11"], ["b12"]]
    assert check_state(tall.init, tall.blocks) == []


def test_blocks_are_the_objects_of_the_block_type():
    d = load_domain(TYPED)
    text = (DATA / "typed_5.pddl").read_text()
    assert blocksworld_roles(d).block_types == ("block",)
    assert blocksworld_view(parse_problem(d, text)).blocks == ("a", "b", "c", "d", "e")


def test_messages_speak_the_domains_names():
    p = load_problem(IPC, DATA / "ipc_blocks_4_0.pddl")
    v = blocksworld_roles(p.domain).vocabulary
    assert check_state({("ontable", "a")}, "ab", v) == [
        "a has nothing on it but (clear a) is missing",
        "b rests on nothing: none of (ontable b), (on b ...), (holding b) holds",
        "b has nothing on it but (clear b) is missing",
        "the arm is neither empty nor holding a block: (handempty) is missing",
    ]
    assert towers({("ontable", "b"), ("on", "a", "b")}, v) == [["b", "a"]]
    unsolvable = parse_problem(p.domain, p.text.replace("(CLEAR A)", ""))
    assert "initial state: a has nothing on it but (clear a) is missing" in diagnose(unsolvable)


# ------------------------------------------------------------------ refusals


def _refused(domain_text: str, name: str = "bad.pddl") -> str:
    with pytest.raises(InputError) as info:
        blocksworld_roles(parse_domain(domain_text, name))
    msg = str(info.value)
    assert "\n" not in msg and info.value.exit_code == EXIT_BAD_INPUT
    assert msg.startswith(f"{name}: not a Blocksworld domain the robot can execute: "), msg
    return msg.split("execute: ", 1)[1]


def _ipc_with(old: str, new: str) -> str:
    text = IPC.read_text()
    assert old in text
    return text.replace(old, new, 1)


def test_refuses_other_domains_naming_the_action():
    with pytest.raises(InputError) as info:
        blocksworld_roles(load_domain(MODELS_DIR / "pddl" / "kitchen.pddl"))
    assert str(info.value).endswith(
        "kitchen.pddl: not a Blocksworld domain the robot can execute: action 'go-to' "
        "neither picks up nor puts down a block (it adds and deletes no (in-hand ...) fact)"
    )
    assert not is_blocksworld(load_domain(MODELS_DIR / "pddl" / "kitchen.pddl"))
    assert _refused((DATA / "blocks_move3.pddl").read_text()).startswith(
        "action 'move-b-to-b' moves a block in one step, never holding it; "
    )
    assert _refused((DATA / "blocks_paint.pddl").read_text()) == (
        "action 'paint' neither picks up nor puts down a block "
        "(it adds and deletes no (holding ...) fact)"
    )


@pytest.mark.parametrize(
    "old, new, expected",
    [
        (  # unstack that does not need the block clear
            "(and (on ?x ?y) (clear ?x) (handempty))",
            "(and (on ?x ?y) (handempty))",
            "action 'unstack' (pick from a block, ?x held) lacks the precondition (clear ?x)",
        ),
        (  # a stack that leaves the block below clear
            "(not (clear ?y)) (clear ?x)",
            "(clear ?x)",
            "action 'stack' (place on a block, ?x held) does not delete (clear ?y)",
        ),
        (  # an action with a parameter that plays no part
            "(:action pickup\n    :parameters (?x)",
            "(:action pickup\n    :parameters (?x ?z)",
            "action 'pickup' (pick from the table, ?x held) has parameter ?z, "
            "neither the block nor its support",
        ),
        (  # a pickup that leaves the hand empty: the arm could hold two blocks
            "(not (handempty)) (holding ?x)))",
            "(holding ?x)))",
            "action 'pickup' (pick from the table, ?x held) does not delete (handempty)",
        ),
        (  # a putdown that also marks the block: something the robot cannot do
            "(clear ?x) (handempty) (ontable ?x)))",
            "(clear ?x) (handempty) (ontable ?x) (clear ?x)))",
            None,
        ),
    ],
)
def test_refuses_actions_that_do_something_else(old, new, expected):
    text = _ipc_with(old, new)
    if expected is None:  # a repeated effect is the same effect
        assert is_blocksworld(parse_domain(text, "ok.pddl"))
    else:
        assert _refused(text) == expected


def test_refuses_extra_effects_and_parameters():
    marked = _ipc_with("(ontable ?x)))", "(ontable ?x) (marked ?x)))").replace(
        "(:predicates (on ?x ?y)", "(:predicates (marked ?x) (on ?x ?y)"
    )
    assert _refused(marked).startswith("action 'putdown' changes 'marked', which means none of")
    twice = _ipc_with("(ontable ?x)))", "(ontable ?x) (clear ?y)))").replace(
        "(:action putdown\n    :parameters (?x)", "(:action putdown\n    :parameters (?x ?y)"
    )
    assert _refused(twice) == (
        "action 'putdown' (place on the table, ?x held) also adds (clear ?y); "
        "has parameter ?y, neither the block nor its support"
    )


def test_refuses_missing_hand_empty_and_extra_predicates():
    text = IPC.read_text().replace("(not (handempty))", "").replace("(handempty)", "")
    text = text.replace("(predicates (on ?x ?y)", "(predicates (handempty) (on ?x ?y)")
    assert "hand empty" in _refused(text)
    triple = _ipc_with("(holding ?x))", "(holding ?x) (at ?x ?y ?z))")
    triple = triple.replace("(not (on ?x ?y)))))", "(not (on ?x ?y)) (at ?x ?y ?x))))")
    assert _refused(triple) == (
        "action 'unstack' changes predicate 'at' of 3 arguments "
        "(Blocksworld predicates take at most two)"
    )
    extra = _ipc_with("(holding ?x))", "(holding ?x) (moved ?x))").replace(
        "(not (on ?x ?y)))))", "(not (on ?x ?y)) (moved ?x))))"
    )
    assert _refused(extra).startswith("action 'unstack' changes 'moved', which means none of ")


# ------------------------------------------------------------------ generators


def test_default_generator_output_is_unchanged():
    """The suite and earlier benchmarks rely on these exact texts."""
    assert random_problem(5, 0) == (
        "(define (problem random-5-blocks-seed-0)\n"
        "  (:domain blocksworld)\n"
        "  (:objects a b c d e)\n"
        "  (:init (on-table a) (on-table b) (on-table c) (on e c) (on d e) (clear a) (clear b)"
        " (clear d) (arm-empty))\n"
        "  (:goal (and (on-table d) (on b d) (on e b) (on c e) (on a c))))\n"
    )


@pytest.mark.parametrize("style", ["exercise", "ipc", "typed"])
def test_generated_problems_in_every_naming(style):
    domain = load_domain(NAMINGS[style].domain_file)
    for n, seed in [(3, 0), (7, 1), (12, 2)]:
        kw = dict(tall=True, max_height=10, goal_max_height=9, partial=True)
        text = random_problem(n, seed, style, **kw)
        assert text == random_problem(n, seed, style, **kw)
        view = blocksworld_view(parse_problem(domain, text))
        names = [f"b{i}" for i in range(1, n + 1)] if style != "exercise" else None
        assert names is None or list(view.blocks) == names
        assert check_state(view.init, view.blocks) == []
        assert max(len(t) for t in towers(view.init)) <= 10
        assert check_goal(view.goal) == []
        assert view.goal and all(f[0] == "on" for f in view.goal) or len(view.goal) == 1
    full = blocksworld_view(parse_problem(domain, random_problem(12, 2, style)))
    part = blocksworld_view(parse_problem(domain, random_problem(12, 2, style, partial=True)))
    assert len(part.goal) < len(full.goal) and not any(f[0] == "on-table" for f in part.goal)


def test_tower_heights():
    import random

    blocks = [f"b{i}" for i in range(1, 13)]
    tall = random_towers(blocks, random.Random(0), max_height=10, tall=True)
    assert max(map(len, tall)) == 10 and sorted(b for t in tall for b in t) == sorted(blocks)
    capped = random_towers(blocks, random.Random(1), max_height=2)
    assert max(map(len, capped)) <= 2
    with pytest.raises(InputError, match="max_height must be a positive integer"):
        random_problem(5, 0, max_height=0)
    with pytest.raises(InputError, match="unknown naming 'strips'"):
        random_problem(5, 0, "strips")


def test_typed_objects_are_checked_with_positions(tmp_path):
    bad = tmp_path / "p.pddl"
    bad.write_text((DATA / "typed_5.pddl").read_text().replace("- block", "- blok"))
    with pytest.raises(
        PddlError, match=r"p\.pddl:5:25: type 'blok' is not declared .*did you mean 'block'"
    ):
        load_problem(TYPED, bad)
