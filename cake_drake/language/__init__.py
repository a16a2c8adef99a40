"""Language plans: SayCan-style transcripts mapped onto a PDDL domain.

A transcript's numbered steps go through a small lexicon (:mod:`.lexicon`) to
ground actions, are simulated against a problem with the symbolic layer's
STRIPS semantics, and are compared with a planner's plan (:mod:`.mapping`);
:mod:`.report` renders the result. The CLI is ``python -m cake_drake.saycan``.
"""

from cake_drake import MODELS_DIR
from cake_drake.language.lexicon import NOUN_ALIASES, VERBS, MethodStep, Verb
from cake_drake.language.mapping import (
    DONE,
    MAPS_CLEANLY,
    MAPS_TO_SEVERAL,
    NO_SCHEMA,
    NOT_REACHED,
    PRECONDITION_FAILS,
    Analysis,
    StepResult,
    analyse,
    side_by_side,
)
from cake_drake.language.report import render_markdown, render_text, write_outputs
from cake_drake.language.transcript import Step, Transcript, load_transcript, parse_transcript

#: The kitchen domain and the default kitchen (no goal).
KITCHEN_DOMAIN = MODELS_DIR / "pddl" / "kitchen.pddl"
KITCHEN_DEFAULT = MODELS_DIR / "pddl" / "kitchen_default.pddl"
TRANSCRIPTS_DIR = MODELS_DIR / "transcripts"

__all__ = [
    "DONE",
    "KITCHEN_DEFAULT",
    "KITCHEN_DOMAIN",
    "MAPS_CLEANLY",
    "MAPS_TO_SEVERAL",
    "NOT_REACHED",
    "NOUN_ALIASES",
    "NO_SCHEMA",
    "PRECONDITION_FAILS",
    "TRANSCRIPTS_DIR",
    "VERBS",
    "Analysis",
    "MethodStep",
    "Step",
    "StepResult",
    "Transcript",
    "Verb",
    "analyse",
    "load_transcript",
    "parse_transcript",
    "render_markdown",
    "render_text",
    "side_by_side",
    "write_outputs",
]
