"""The lexicon: SayCan skill phrases -> action schemas, noun phrases -> objects.

It is plain data, meant to be read (docs/saycan.md prints it as a table):

- :data:`VERBS`: each skill has phrase patterns (``{x}``, ``{y}`` are noun slots)
  and one or more *methods*, each a sequence of action schemas with some
  parameters filled from the slots. A method of several actions is an implicit
  decomposition: what an HTN method would state explicitly. When a skill has
  several methods (``pick up`` from a counter, or out of an open drawer), the
  first that applies in the current state is used.
- Parameters no slot fills (where the robot stands, where the item lies) are
  bound from the current state: the binding that satisfies the preconditions.
- :data:`NOUN_ALIASES`: extra names for problem objects. Every object is also
  known by its own name with ``-`` read as a space (``coke-can``: "coke can").
  Articles are ignored; "it" is the last item mentioned; "you" and "me" are the
  user. A noun naming a thing where a location is needed (``go to the drawer``)
  stands for the place where that thing is.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MethodStep:
    """One action of a method: a schema name and parameters filled from slots or constants.

    ``args`` maps a schema parameter (``?i``) to a slot (``x``/``y``) or to an
    object name (``trash-can``).
    """

    schema: str
    args: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class Verb:
    """A skill: how it is phrased and what it stands for in the domain."""

    skill: str
    phrases: tuple[str, ...]
    methods: tuple[tuple[MethodStep, ...], ...]


def _m(*steps: tuple[str, dict[str, str]]) -> tuple[MethodStep, ...]:
    return tuple(MethodStep(schema, tuple(args.items())) for schema, args in steps)


#: Phrases that end a transcript (SayCan's "done").
END_PHRASES = ("done", "i am done", "i'm done", "finished", "task complete", "terminate")

#: The skill vocabulary, in the order phrases are tried (more specific first).
VERBS: tuple[Verb, ...] = (
    Verb(
        "throw away",
        ("throw away {x}", "throw {x} away", "throw {x} in the trash", "discard {x}"),
        (_m(("go-to", {"?to": "trash-can"}), ("put-in", {"?i": "x", "?c": "trash-can"})),),
    ),
    Verb(
        "clean up",
        ("clean up {x}", "clean {x}"),
        (_m(("go-to", {"?to": "x"}), ("wipe", {"?m": "x"})),),
    ),
    Verb("wipe", ("wipe up {x}", "wipe {x}"), (_m(("wipe", {"?m": "x"})),)),
    Verb(
        "put in",
        ("put {x} in {y}", "put {x} into {y}", "place {x} in {y}", "place {x} into {y}"),
        (_m(("put-in", {"?i": "x", "?c": "y"})),),
    ),
    Verb(
        "bring it to you",
        ("bring {x} to you", "bring {x} to the user", "bring {x} over", "bring {x} back"),
        (_m(("bring-to-user", {"?i": "x"})),),
    ),
    Verb("find", ("find {x}", "look for {x}", "locate {x}"), (_m(("find", {"?i": "x"})),)),
    Verb(
        "go to",
        ("go to {x}", "move to {x}", "navigate to {x}", "walk to {x}"),
        (_m(("go-to", {"?to": "x"})),),
    ),
    Verb(
        "pick up",
        ("pick up {x}", "pick {x} up", "grab {x}", "take {x}"),
        (_m(("pick-up", {"?i": "x"})), _m(("take-out", {"?i": "x"}))),
    ),
    Verb(
        "put down",
        ("put down {x}", "put {x} down", "place {x} down", "drop {x}"),
        (_m(("put-down", {"?i": "x"})),),
    ),
    Verb("open", ("open {x}",), (_m(("open", {"?c": "x"})),)),
    Verb("close", ("close {x}", "shut {x}"), (_m(("close", {"?c": "x"})),)),
)

#: Extra names for objects of the kitchen problems (object names work as they are).
NOUN_ALIASES: dict[str, str] = {
    "coke": "coke-can",
    "can of coke": "coke-can",
    "coke can": "coke-can",
    "can": "coke-can",
    "sprite": "sprite-can",
    "can of sprite": "sprite-can",
    "water": "water-bottle",
    "bottle of water": "water-bottle",
    "bag of chips": "chips",
    "chip": "chips",
    "snack bar": "energy-bar",
    "granola": "granola-bar",
    "drawer": "top-drawer",
    "trash": "trash-can",
    "trash bin": "trash-can",
    "bin": "trash-can",
    "garbage": "trash-can",
    "close counter": "near-counter",
    "spilled coke": "spill",
    "mess": "spill",
    "you": "user",
    "me": "user",
}

#: Words dropped in front of a noun phrase.
ARTICLES = ("a", "an", "the", "some", "my", "your", "this", "that")

#: Words that refer back to the last item mentioned.
PRONOUNS = ("it", "them", "that one")

#: How unmet facts read in plain words ({0}, {1} are the arguments).
GLOSSES: dict[str, str] = {
    "at-location": "{0} is not at {1}",
    "in-hand": "the robot is not holding {0}",
    "hand-empty": "the robot's hand is not empty",
    "is-open": "{0} is not open",
    "is-closed": "{0} is not closed",
    "contains": "{1} is not in {0}",
    "container-at": "{0} is not at {1}",
    "openable": "{0} cannot be opened or closed",
    "can-wipe": "{0} cannot wipe anything",
    "cleaned": "{0} is not cleaned",
}


def verb_vocabulary() -> list[str]:
    """The skills, as listed in messages."""
    return [v.skill for v in VERBS]
