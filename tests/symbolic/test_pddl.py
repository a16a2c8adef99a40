"""PDDL parsing: what is accepted, and one-line file:line:col errors for what is not."""

from __future__ import annotations

import pytest

from cake_drake.errors import InputError, PddlError
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    PROBLEM_5,
    load_domain,
    load_problem,
    parse_domain,
    parse_problem,
)
from cake_drake.symbolic.sexpr import Atom, SList, parse_sexprs

PROBLEM_TEXT = PROBLEM_5.read_text()
DOMAIN_TEXT = BLOCKSWORLD_DOMAIN.read_text()

TYPED_DOMAIN = """(define (domain kitchen-mini)
  (:requirements :strips :typing)
  (:types item place - object drink - item)
  (:constants user - place)
  (:predicates (at ?i - item ?p - place) (robot-at ?p - place) (holding ?i - item) (free))
  (:action pick :parameters (?i - item ?p - place)
    :precondition (and (at ?i ?p) (robot-at ?p) (free))
    :effect (and (holding ?i) (not (at ?i ?p)) (not (free))))
  (:action go :parameters (?from ?to - place)
    :precondition (robot-at ?from)
    :effect (and (robot-at ?to) (not (robot-at ?from)))))
"""


@pytest.fixture(scope="module")
def domain():
    return load_domain(BLOCKSWORLD_DOMAIN)


def test_domain_contents(domain):
    assert domain.name == "blocksworld"
    assert sorted(domain.predicates) == ["arm-empty", "clear", "holding", "on", "on-table"]
    assert sorted(domain.actions) == ["pick-up", "put-down", "stack", "unstack"]
    stack = domain.actions["stack"]
    assert stack.params == (("?x", "object"), ("?y", "object"))
    assert set(stack.pre) == {("holding", "?x"), ("clear", "?y")}
    assert set(stack.delete) == {("holding", "?x"), ("clear", "?y")}


def test_sexpr_positions():
    (node,) = parse_sexprs("; c\n(define\n  (Domain X))", "f")
    assert isinstance(node, SList) and (node.line, node.col) == (2, 1)
    inner = node.items[1]
    assert inner.items[0] == Atom("domain", 3, 4)


def test_typed_domain_and_problem():
    d = parse_domain(TYPED_DOMAIN, "k.pddl")
    assert d.is_subtype("drink", "item") and not d.is_subtype("place", "item")
    p = parse_problem(
        d,
        """(define (problem p) (:domain kitchen-mini)
             (:objects coke - drink counter - place)
             (:init (at coke counter) (robot-at counter) (free))
             (:goal (and (at coke user))))""",
        "p.pddl",
    )
    assert p.object_types == {"user": "place", "coke": "drink", "counter": "place"}
    assert p.objects_of_type("place") == ["counter", "user"]
    assert p.goal == {("at", "coke", "user")}


def test_problem_without_goal_only_when_allowed():
    d = parse_domain(TYPED_DOMAIN)
    text = "(define (problem p) (:domain kitchen-mini) (:objects c - drink) (:init (free)))"
    with pytest.raises(PddlError, match=r"^<string>:1:1: problem 'p' has no \(:goal"):
        parse_problem(d, text)
    p = parse_problem(d, text, require_goal=False)
    assert not p.has_goal and p.goal == frozenset()


def _problem_error(text: str) -> str:
    with pytest.raises(PddlError) as e:
        parse_problem(load_domain(BLOCKSWORLD_DOMAIN), text, "p.pddl")
    msg = str(e.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize(
    "old, new, expected",
    [
        (
            "(clear a) (clear d)",
            "(clear a) (clr d)",
            "p.pddl:11:16: predicate 'clr' is not defined in domain 'blocksworld' "
            "(did you mean 'clear'? defined: arm-empty, clear, holding, on, on-table)",
        ),
        (
            "(on d e) (on-table e))))",
            "(on d e) (ontable e))))",
            "p.pddl:13:52: predicate 'ontable' is not defined",
        ),
        (
            "(clear a) (clear d)",
            "(clear a) (clear f)",
            "p.pddl:11:22: object 'f' is not declared (declared: a, b, c, d, e)",
        ),
        ("(on c d)", "(on c z)", "p.pddl:13:39: object 'z' is not declared"),
        (
            "(arm-empty))",
            "(arm-empty a))",
            "p.pddl:12:5: predicate 'arm-empty' takes 0 arguments (arm-empty), got 1",
        ),
        ("(on-table c)", "(on-table c a)", "p.pddl:9:23: predicate 'on-table' takes 1 argument"),
        (
            "(:domain blocksworld)",
            "(:domain logistics)",
            "p.pddl:6:12: problem 'problem-5' is for domain 'logistics' but",
        ),
        (
            "(on d e) (on-table e)\n",
            "(on d e (on-table e)\n",
            "p.pddl:13:3: (:goal ...) is nested inside (:init ...) opened at line 8: "
            "a ')' is missing between line 8 and line 13",
        ),
        ("(on-table e))))", "(on-table e)))", "p.pddl:5:1: this '(' is never closed"),
        ("(on-table e))))", "(on-table e)))))", "p.pddl:13:66: unexpected ')'"),
        ("(:goal (and", "(:goal (or", "p.pddl:13:10: in the :goal: disjunction (or ...)"),
        ("(:goal (and", "(:goal (and (not (clear a))", "negative conditions (not ...)"),
        ("(clear a)", "(clear ?x)", "p.pddl:11:12: variable ?x in a ground fact"),
        ("(:objects a b c d e)", "(:objects a b c d e a)", "object 'a' is already declared"),
        ("(:objects a b c d e)", "(:objects a b c d - block e)", "domain 'blocksworld' is untyped"),
        ("(:init", "(:inits", "p.pddl:8:4: section :inits is not supported here"),
    ],
)
def test_problem_errors(old, new, expected):
    text = PROBLEM_TEXT.replace(old, new, 1)
    assert text != PROBLEM_TEXT
    assert _problem_error(text).startswith(expected) or expected in _problem_error(text)


def test_problem_error_positions_are_exact():
    assert _problem_error(PROBLEM_TEXT.replace("(clear d)", "(clr d)")).startswith("p.pddl:11:16:")


@pytest.mark.parametrize(
    "old, new, expected",
    [
        ("(:requirements :strips)", "(:requirements :strips :fluents)", "requirement :fluents"),
        (":precondition (holding ?x)", ":precondition (hold ?x)", "predicate 'hold' is not"),
        ("(on ?x ?y) (clear ?x) (arm-empty))", "(on ?x ?z) (clear ?x) (arm-empty))", "?z is not"),
        ("(on ?x ?y) (clear ?x) (arm-empty))", "(on ?x) (clear ?x) (arm-empty))", "takes 2"),
        (":precondition (holding ?x)", ":precondition (not (holding ?x))", "negative condition"),
        (":effect (and (on ?x ?y)", ":effect (and (when (clear ?x) (on ?x ?y))", "conditional"),
        ("(:action put-down", "(:action pick-up", "action 'pick-up' is defined twice"),
        (
            ":parameters (?x)\n    :precondition (holding",
            ":params (?x)\n    :precondition (holding",
            "expected :parameters",
        ),
    ],
)
def test_domain_errors(old, new, expected):
    text = DOMAIN_TEXT.replace(old, new, 1)
    assert text != DOMAIN_TEXT
    with pytest.raises(PddlError) as e:
        parse_domain(text, "d.pddl")
    assert expected in str(e.value) and str(e.value).startswith("d.pddl:")


def test_swapped_files_are_named():
    with pytest.raises(PddlError, match="this is a problem file, expected a domain file"):
        load_problem(PROBLEM_5, BLOCKSWORLD_DOMAIN)


def test_type_errors():
    d = parse_domain(TYPED_DOMAIN)
    good = """(define (problem p) (:domain kitchen-mini) (:objects coke - drink here - place)
        (:init (robot-at here) (free)) (:goal (and (holding coke))))"""
    parse_problem(d, good)
    with pytest.raises(PddlError, match="'here' has type 'place' but argument 1 of"):
        parse_problem(d, good.replace("(holding coke)", "(holding here)"))
    with pytest.raises(PddlError, match="type 'snack' is not declared in :types"):
        parse_problem(d, good.replace("coke - drink", "coke - snack"))
    with pytest.raises(PddlError, match="object 'user' is a domain constant"):
        parse_problem(d, good.replace("here - place", "user - place"))


@pytest.mark.parametrize(
    "content, expected",
    [
        (b"", "is empty; expected a PDDL problem file"),
        (b"  \n\t\n", "is empty"),
        (b"; just a comment\n", "contains no PDDL (only comments)"),
        (b"\x00\x01\x02", "not a text file (NUL byte at offset 0)"),
        (b"(define \xff\xfe)", "not a UTF-8 text file (invalid byte at offset 8)"),
        (b"hello", "expected (define (problem NAME) ...), got hello"),
        (b"(define (problem p)) (extra)", "unexpected text after the (define ...) form"),
    ],
)
def test_unusable_files(tmp_path, content, expected):
    f = tmp_path / "p.pddl"
    f.write_bytes(content)
    with pytest.raises(InputError) as e:
        load_problem(BLOCKSWORLD_DOMAIN, f)
    assert expected in str(e.value) and str(e.value).startswith(str(f))


def test_missing_files_and_directories(tmp_path):
    with pytest.raises(InputError, match="no such PDDL domain file"):
        load_problem(tmp_path / "nope.pddl", PROBLEM_5)
    with pytest.raises(InputError, match="is a directory"):
        load_problem(BLOCKSWORLD_DOMAIN, tmp_path)
