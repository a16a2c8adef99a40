"""Language plans: SayCan-style transcripts mapped onto a PDDL domain.

A transcript's numbered steps (:mod:`.transcript`) go through a small lexicon
(:mod:`.lexicon`): each skill phrase stands for HTN-style methods
(:mod:`.methods`), the first whose precondition holds in the current state
decides which ground actions the step becomes (:mod:`.reading` reads a step's
words). The actions are simulated with the symbolic layer's STRIPS semantics and
compared with a planner's plan (:mod:`.mapping`); :mod:`.objects` declares the
objects a transcript names that a problem lacks; :mod:`.report` renders the result
and its note. The CLI is ``python -m cake_drake.saycan``.
"""

from cake_drake.language.lexicon import END_PHRASES, NOUN_ALIASES, VERBS, Verb
from cake_drake.language.mapping import (
    AFTER_DONE,
    AMBIGUOUS,
    DONE,
    MAPS_CLEANLY,
    MAPS_TO_SEVERAL,
    MAPS_VIA_METHOD,
    NO_SCHEMA,
    NOT_REACHED,
    PRECONDITION_FAILS,
    Analysis,
    StepResult,
    analyse,
    problem_with_goal,
    side_by_side,
)
from cake_drake.language.methods import Method, MethodStep, method_bindings
from cake_drake.language.objects import missing_objects, with_objects
from cake_drake.language.report import (
    SAYCAN_OUTPUTS,
    render_markdown,
    render_note,
    render_text,
    write_outputs,
)
from cake_drake.language.transcript import Step, Transcript, load_transcript, parse_transcript
from cake_drake.paths import MODELS_DIR

#: The kitchen domain; the default kitchen (SayCan's, no goal); the same with the
#: things SayCan's planning prompt names.
KITCHEN_DOMAIN = MODELS_DIR / "pddl" / "kitchen.pddl"
KITCHEN_DEFAULT = MODELS_DIR / "pddl" / "kitchen_default.pddl"
KITCHEN_PROMPT = MODELS_DIR / "pddl" / "kitchen_prompt.pddl"
TRANSCRIPTS_DIR = MODELS_DIR / "transcripts"

__all__ = [
    "missing_objects",
    "with_objects",
    "AFTER_DONE",
    "AMBIGUOUS",
    "DONE",
    "END_PHRASES",
    "KITCHEN_DEFAULT",
    "KITCHEN_DOMAIN",
    "KITCHEN_PROMPT",
    "MAPS_CLEANLY",
    "MAPS_TO_SEVERAL",
    "MAPS_VIA_METHOD",
    "NOT_REACHED",
    "NOUN_ALIASES",
    "NO_SCHEMA",
    "PRECONDITION_FAILS",
    "TRANSCRIPTS_DIR",
    "VERBS",
    "Analysis",
    "Method",
    "MethodStep",
    "Step",
    "StepResult",
    "Transcript",
    "Verb",
    "analyse",
    "load_transcript",
    "method_bindings",
    "parse_transcript",
    "problem_with_goal",
    "render_markdown",
    "render_note",
    "render_text",
    "side_by_side",
    "write_outputs",
    "SAYCAN_OUTPUTS",
]
