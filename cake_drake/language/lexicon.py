"""The lexicon: SayCan's skill phrases -> methods -> action schemas; noun phrases -> objects.

Plain data, meant to be read (docs/saycan.md prints it as a table):

- :data:`VERBS`: each skill has phrase patterns (``{x}``, ``{y}`` are noun slots)
  and its :class:`~cake_drake.language.methods.Method` list, tried in order: the
  first whose precondition holds in the current state is used. SayCan's own
  skills are *find*, *pick up*, *put down*, *go to*, *bring it to you*, *open*,
  *close* and the end marker *done* (its prompts also write "tell you I'm done").
  *put in*, *wipe*, *clean up* and *throw away* are ours, for the teaching cases.
- Parameters no slot or method variable fills (where the robot stands, where the
  item lies) are bound from the current state.
- Nouns: every object is known by its name with ``-`` read as a space
  (``rice-chips``: "rice chips") and by :data:`NOUN_ALIASES`. Articles are dropped;
  a plural falls back to the singular; a packaging word is dropped when the rest
  names an object ("coke can", "can of coke"); a noun that ends the names of several
  objects ("counter": close counter, far counter) is *ambiguous*; one that ends the
  name of exactly one ("bar") names it. "It" is the last item mentioned.
"""

from __future__ import annotations

from dataclasses import dataclass

from cake_drake.language.methods import Method, MethodStep


@dataclass(frozen=True)
class Verb:
    """A skill: how it is phrased, the methods it stands for, and what its ``{x}`` names."""

    skill: str
    phrases: tuple[str, ...]
    methods: tuple[Method, ...]
    x_is_item: bool = True  # "it" may refer back to {x}


def _steps(*steps: tuple[str, dict[str, str]]) -> tuple[MethodStep, ...]:
    return tuple(MethodStep(schema, tuple(args.items())) for schema, args in steps)


def _literal(schema: str, **args: str) -> Method:
    return Method(schema, _steps((schema, {f"?{k}": v for k, v in args.items()})), literal=True)


#: Phrases that end a transcript: SayCan's "done" and "tell you I'm done", and kin.
END_PHRASES = (
    "done",
    "done()",
    "i'm done",
    "i am done",
    "tell you i'm done",
    "tell you i am done",
    "tell you that i'm done",
    "finished",
    "task complete",
    "terminate",
)

#: The skill vocabulary, in the order phrases are tried (more specific first).
VERBS: tuple[Verb, ...] = (
    Verb(
        "throw away",
        ("throw away {x}", "throw {x} away", "throw {x} in the trash", "discard {x}"),
        (
            Method(
                "put-in-trash-here",
                _steps(("put-in", {"?i": "x", "?c": "trash-can", "?l": "?l"})),
                pre=(("at-location", "robot", "?l"), ("container-at", "trash-can", "?l")),
                why="the robot already stands at {l}, by the trash can",
            ),
            Method(
                "go-to-trash-then-put-in",
                _steps(
                    ("go-to", {"?to": "trash-can"}),
                    ("put-in", {"?i": "x", "?c": "trash-can"}),
                ),
                why="the trash can is elsewhere: go there, then put {x} in",
            ),
        ),
    ),
    Verb(
        "clean up",
        ("clean up {x}", "clean {x}"),
        (
            Method(
                "wipe-here",
                _steps(("wipe", {"?m": "x", "?l": "?l"})),
                pre=(("at-location", "robot", "?l"), ("at-location", "x", "?l")),
                why="the robot already stands at {l}, where {x} is",
            ),
            Method(
                "go-to-then-wipe",
                _steps(("go-to", {"?to": "x"}), ("wipe", {"?m": "x"})),
                why="{x} is elsewhere: go there, then wipe",
            ),
        ),
        x_is_item=False,
    ),
    Verb("wipe", ("wipe up {x}", "wipe {x}"), (_literal("wipe", m="x"),), x_is_item=False),
    Verb(
        "put in",
        ("put {x} in {y}", "put {x} into {y}", "place {x} in {y}", "place {x} into {y}"),
        (_literal("put-in", i="x", c="y"),),
    ),
    Verb(
        "bring it to you",
        ("bring {x} to you", "bring {x} to the user", "bring {x} over", "bring {x} back"),
        (_literal("bring-to-user", i="x"),),
    ),
    Verb("find", ("find {x}", "look for {x}", "locate {x}"), (_literal("find", i="x"),)),
    Verb(
        "go to",
        ("go to {x}", "move to {x}", "navigate to {x}", "walk to {x}"),
        (_literal("go-to", to="x"),),
        x_is_item=False,
    ),
    Verb(
        "pick up",
        ("pick up {x}", "pick {x} up", "grab {x}", "take {x}"),
        (
            Method(
                "take-out-of-container",
                _steps(("take-out", {"?i": "x", "?c": "?c"})),
                pre=(("contains", "?c", "x"),),
                why="{x} is inside {c}: 'pick up' means take it out",
            ),
            _literal("pick-up", i="x"),
        ),
    ),
    Verb(
        "put down",
        ("put down {x}", "put {x} down", "place {x} down", "drop {x}", "let go of {x}"),
        (
            Method(
                "put-into-container-here",
                _steps(("put-in", {"?i": "x", "?c": "?c", "?l": "?l"})),
                pre=(
                    ("at-location", "robot", "?l"),
                    ("container-at", "?c", "?l"),
                    ("is-open", "?c"),
                ),
                why="the robot stands at {l}, where the open {c} stands: "
                "'put down' there means put {x} in",
            ),
            _literal("put-down", i="x"),
        ),
    ),
    Verb("open", ("open {x}",), (_literal("open", c="x"),), x_is_item=False),
    Verb("close", ("close {x}", "shut {x}"), (_literal("close", c="x"),), x_is_item=False),
)

#: Extra names for objects of the kitchen problems (object names work as they are).
NOUN_ALIASES: dict[str, str] = {
    "7up": "seven-up",
    "7 up": "seven-up",
    "coca cola": "coke",
    "grapefruit drink": "grapefruit-soda",
    "lime drink": "lime-soda",
    "red bull": "redbull",
    "water": "water-bottle",
    "trash": "trash-can",
    "trash bin": "trash-can",
    "trashcan": "trash-can",
    "garbage": "trash-can",
    "bin": "trash-can",
    "spilled coke": "spill",
    "mess": "spill",
    "you": "user",
    "me": "user",
}

#: Packaging words: "coke can", "can of coke" and "bag of rice chips" name the drink or the chips.
PACKAGING = ("can", "bottle", "bag", "box", "cup", "glass", "packet")

#: Words dropped in front of a noun phrase.
ARTICLES = ("a", "an", "the", "some", "my", "your", "this", "that", "one")

#: Words that refer back to the last item mentioned.
PRONOUNS = ("it", "them", "that one", "this one")

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
