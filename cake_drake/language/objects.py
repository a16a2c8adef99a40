"""``--add-objects``: the objects a transcript names that a problem lacks, declared.

:func:`missing_objects` finds them, typed by the schema parameter each noun fills;
:func:`with_objects` declares them, each thing at a place of its own that no other fact
names (nobody said where it is).
"""

from __future__ import annotations

import re

from cake_drake.errors import InputError
from cake_drake.language.lexicon import PRONOUNS, Verb
from cake_drake.language.reading import _singulars, _strip_articles, match_verb, noun_candidates
from cake_drake.language.transcript import Transcript
from cake_drake.symbolic import Problem, parse_problem


def _slot_type(verb: Verb, slot: str, problem: Problem) -> str | None:
    """The type the domain gives the schema parameter a verb's ``{slot}`` fills."""
    for method in verb.methods:
        for step in method.steps:
            schema = problem.domain.actions.get(step.schema)
            if schema is None:
                continue
            for param, value in step.args:
                if value == slot:
                    for var, kind in schema.params:
                        if var == param:
                            return kind
    return None


def missing_objects(transcript: Transcript, problem: Problem) -> list[tuple[str, str]]:
    """(name, type) of every object the transcript's steps name that the problem lacks,
    typed by the schema parameter its noun fills (an item, a location, a container), in
    the order the steps name them."""
    found: dict[str, str] = {}
    for step in transcript.steps:
        matched = match_verb(step.text) if step.text else None
        if matched is None:
            continue
        verb, phrases = matched
        for slot, phrase in sorted(phrases.items()):
            p = _strip_articles(phrase)
            if not p or p in PRONOUNS or noun_candidates(p, problem):
                continue
            kind = _slot_type(verb, slot, problem)
            name = re.sub(r"[^a-z0-9]+", "-", _singulars(p)[-1]).strip("-")
            if kind and name and name not in found and name not in problem.object_types:
                found[name] = kind
    return list(found.items())


def _where_predicates(problem: Problem, kind: str) -> list[str]:
    """The predicates that say where a thing of type ``kind`` is: ``(P ?x - T ?l - location)``
    with ``kind`` a subtype of ``T`` (``at-location`` for an item, ``container-at`` for a
    container; none for a location)."""
    domain = problem.domain
    return [
        pred.name
        for pred in domain.predicates.values()
        if len(pred.params) == 2
        and pred.params[1][1] == "location"
        and domain.is_subtype(kind, pred.params[0][1])
    ]


def _section_end(text: str, start: int) -> int:
    """The index of the parenthesis that closes the one opened at ``start``."""
    depth, i = 0, start
    while i < len(text):
        depth += {"(": 1, ")": -1}.get(text[i], 0)
        if depth == 0:
            return i
        i += 1
    return i


def with_objects(problem: Problem, objects: list[tuple[str, str]]) -> Problem:
    """``problem`` with ``objects`` declared, each thing that stands somewhere at a place of
    its own, ``<name>-spot``: a location no other fact names.

    Nobody said where an added object is, so no place of the kitchen is chosen for it: the
    spot only says that it is somewhere, and only a step that goes where the object is
    (``find``) reaches it. A step that needs the object elsewhere, in hand or where the
    robot already stands fails on what the transcript itself assumed.
    """
    if not objects:
        return problem
    text = problem.text
    m = re.search(r"\(:objects\b", text, re.IGNORECASE)
    if m is None:
        raise InputError(f"{problem.problem_path}: no (:objects ...) to add objects to")
    declared = set(problem.object_types) | {name for name, _ in objects}
    spots: list[str] = []
    facts: list[str] = []
    for name, kind in objects:
        where = _where_predicates(problem, kind)
        if not where:
            continue
        spot = f"{name}-spot"
        while spot in declared:
            spot += "-"
        declared.add(spot)
        spots.append(spot)
        facts += [f"({pred} {name} {spot})" for pred in where]
    i = _section_end(text, m.start())
    added = "".join(f"\n    {name} - {kind}" for name, kind in objects)
    added += "".join(f"\n    {spot} - location" for spot in spots)
    composed = text[:i] + added + "  ; added by --add-objects\n  " + text[i:]
    if facts:
        init = re.search(r"\(:init\b", composed, re.IGNORECASE)
        if init is None:
            raise InputError(f"{problem.problem_path}: no (:init ...) to place objects in")
        j = init.end()
        where_facts = " ".join(facts)
        composed = (
            composed[:j]
            + "\n    ; added by --add-objects: each in a place of its own, where nobody said\n"
            + f"    {where_facts}"
            + composed[j:]
        )
    return parse_problem(
        problem.domain, composed, problem.problem_path, require_goal=problem.has_goal
    )
