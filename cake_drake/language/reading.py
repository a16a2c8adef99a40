"""Reading a step's words: the skill phrase it matches and the objects its nouns name.

A step's text is matched against the lexicon's skill phrases (:func:`match_verb`); each
noun slot is resolved to one object of the problem (:func:`resolve_noun`: exact name,
alias, plural, packaging word, head noun), and "it" to the last item named. A noun that
names nothing raises :class:`_NoSchema`, one that names several :class:`_Ambiguous`; the
mapping (:mod:`.mapping`) turns both into a step's verdict.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from cake_drake.language.lexicon import (
    ARTICLES,
    NOUN_ALIASES,
    PACKAGING,
    PRONOUNS,
    VERBS,
    Verb,
    verb_vocabulary,
)
from cake_drake.symbolic import Problem

_PARTICLES = {"up", "down", "on", "off", "away", "in", "out", "over", "back", "to", "for"}


class _NoSchema(Exception):
    def __init__(self, message: str, need: str = ""):
        super().__init__(message)
        self.need = need


class _Ambiguous(Exception):
    def __init__(self, message: str, candidates: tuple[str, ...], need: str):
        super().__init__(message)
        self.candidates = candidates
        self.need = need


def _pattern(phrase: str) -> re.Pattern:
    parts = re.split(r"(\{[xy]\})", phrase)
    rx = "".join(f"(?P<{p[1]}>.+?)" if p in ("{x}", "{y}") else re.escape(p) for p in parts)
    return re.compile(f"^{rx}$")


_PATTERNS: list[tuple[Verb, re.Pattern]] = [(v, _pattern(p)) for v in VERBS for p in v.phrases]


def match_verb(text: str) -> tuple[Verb, dict[str, str]] | None:
    """The first skill phrase matching the whole step text, with its noun slots."""
    for verb, rx in _PATTERNS:
        m = rx.match(text)
        if m:
            return verb, {k: v.strip() for k, v in m.groupdict().items()}
    return None


def _leading_verb(text: str) -> str:
    words = text.split()
    if len(words) > 1 and words[1] in _PARTICLES:
        return " ".join(words[:2])
    return words[0] if words else text


def unknown_verb_message(text: str) -> str:
    """Why no skill phrase matches ``text``: an unknown verb, or a known verb phrased oddly."""
    first = text.split()[0] if text.split() else text
    near = [p for v in VERBS for p in v.phrases if p.split()[0] == first]
    if near:
        return f"no skill phrase fits '{text}' (phrases with '{first}': {', '.join(near)})"
    return (
        f"verb '{_leading_verb(text)}' is not in the lexicon "
        f"(skills: {', '.join(verb_vocabulary())})"
    )


def _listing(names, limit: int = 24) -> str:
    names = list(names)
    shown = ", ".join(names[:limit])
    return shown if len(names) <= limit else f"{shown}, ... ({len(names) - limit} more)"


def _spaced(name: str) -> str:
    return name.replace("-", " ")


def _strip_articles(phrase: str) -> str:
    words = phrase.split()
    while words and words[0] in ARTICLES:
        words = words[1:]
    return " ".join(words)


def _singulars(p: str) -> list[str]:
    out = [p]
    if p.endswith("ies"):
        out.append(p[:-3] + "y")
    if p.endswith("es"):
        out.append(p[:-2])
    if p.endswith("s"):
        out.append(p[:-1])
    return out


def noun_candidates(phrase: str, problem: Problem) -> list[str]:
    """The objects a noun phrase (articles already dropped) may name: none, one or several.

    Exact name, then alias, then a plural read as singular, then a packaging word
    dropped ("coke can", "can of coke"), then the head noun ("counter" ends both
    "close counter" and "far counter").
    """
    objects = problem.object_types
    by_name = {_spaced(o): o for o in objects} | {o: o for o in objects}
    forms = _singulars(phrase)
    for t in forms:
        if t in by_name:
            return [by_name[t]]
        if t in NOUN_ALIASES and NOUN_ALIASES[t] in objects:
            return [NOUN_ALIASES[t]]
    words = phrase.split()
    if len(words) >= 2 and words[-1] in PACKAGING:
        found = noun_candidates(" ".join(words[:-1]), problem)
        if found:
            return found
    if len(words) >= 3 and words[0] in PACKAGING and words[1] == "of":
        found = noun_candidates(" ".join(words[2:]), problem)
        if found:
            return found
    for t in forms:
        heads = sorted({o for name, o in by_name.items() if name.endswith(" " + t)})
        if heads:
            return heads
    return []


@dataclass
class _Reference:
    """What "it" stands for: the last item resolved, or the last item phrase that was not."""

    item: str | None = None
    unresolved: tuple[str, int] | None = None  # (phrase, step number)


def _request_hint(request: str, candidates: tuple[str, ...]) -> str:
    text = " " + re.sub(r"[^a-z0-9 ]+", " ", request.lower()) + " "
    named = [c for c in candidates if f" {_spaced(c)} " in text]
    if len(named) == 1:
        return f"; the request names '{_spaced(named[0])}'"
    return ""


def resolve_noun(
    phrase: str, problem: Problem, ref: _Reference, request: str = "", step: int = 0
) -> str:
    """The problem object a noun phrase names; :class:`_NoSchema` or :class:`_Ambiguous`."""
    p = _strip_articles(phrase)
    if p in PRONOUNS:
        if ref.item is not None:
            return ref.item
        if ref.unresolved is not None:
            said, where = ref.unresolved
            raise _NoSchema(
                f"'{p}' stands for '{said}' (step {where}), which names no object of "
                f"problem '{problem.name}'",
                need=f"'{_strip_articles(said)}' among the problem's objects",
            )
        raise _NoSchema(
            f"'{p}' refers to nothing: no earlier step names an item",
            need="an earlier step that names the item 'it' stands for",
        )
    found = noun_candidates(p, problem) if p else []
    if len(found) == 1:
        return found[0]
    if len(found) > 1:
        cands = tuple(found)
        hint = _request_hint(request, cands)
        raise _Ambiguous(
            f"'{p}' is ambiguous in problem '{problem.name}': it may be "
            f"{', '.join(cands[:-1])} or {cands[-1]}{hint}",
            cands,
            need=f"a referring expression resolved to one object ({' or '.join(cands)})" + hint,
        )
    if step and p and ref is not None:
        ref.unresolved = (p, step)
    raise _NoSchema(
        f"'{p or phrase}' is not an object of problem '{problem.name}' "
        f"(objects: {_listing(sorted(problem.object_types))})",
        need=f"'{p or phrase}' among the problem's objects, with its initial place",
    )


def _resolve_slots(
    verb: Verb, phrases: dict[str, str], problem: Problem, ref: _Reference, request: str, step: int
) -> dict[str, str]:
    """Resolve the step's noun slots, keeping track of what "it" will stand for."""
    slots: dict[str, str] = {}
    for k in sorted(phrases):
        item_slot = k == "x" and verb.x_is_item
        try:
            slots[k] = resolve_noun(phrases[k], problem, ref, request, step if item_slot else 0)
        except _Ambiguous:
            if item_slot:
                ref.item, ref.unresolved = None, (_strip_articles(phrases[k]), step)
            raise
        if item_slot:
            ref.item, ref.unresolved = slots[k], None
    return slots
