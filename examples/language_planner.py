"""A planner plug-in that reads a language model's answer instead of searching.

The answer is plain numbered English, as a language model writes it::

    1. unstack a from b, 2. put down a, 3. pick up c, 4. stack c on d, 5. done

:func:`plan` reads ``answers/<problem name>.txt`` beside this file, maps each step onto
the domain's actions by its verb, and returns the ground actions. The pipeline then
validates them against the problem like any other plan: a step the model got wrong is
refused (exit 1) with the step and its unmet preconditions, before the robot moves.

Use it: ``task: {planner: examples.language_planner:plan}`` in a scenario, or
``--planner examples.language_planner:plan``.
"""

import re
from pathlib import Path

from cake_drake.errors import InputError, NoPlanError
from cake_drake.symbolic import GroundAction, Problem

ANSWERS = Path(__file__).resolve().parent / "answers"

#: Verb patterns -> (action, how many objects). Blocksworld's four actions.
PATTERNS = (
    (re.compile(r"^pick(?:\s+up)?\s+(?:the\s+)?(\w+)$"), "pick-up"),
    (re.compile(r"^put\s+down\s+(?:the\s+)?(\w+)$"), "put-down"),
    (re.compile(r"^unstack\s+(?:the\s+)?(\w+)\s+from\s+(?:the\s+)?(\w+)$"), "unstack"),
    (re.compile(r"^stack\s+(?:the\s+)?(\w+)\s+on(?:to)?\s+(?:the\s+)?(\w+)$"), "stack"),
)


def steps(text: str) -> list[str]:
    """The numbered steps of an answer (after "Robot:", if the prompt is included), in
    order, without their numbers."""
    text = re.split(r"(?i)\brobot:", text)[-1]
    parts = re.split(r"(?:^|[\s,;])\d+\s*[.)]\s*", " ".join(text.split()))
    return [p.strip(" ,;.").lower() for p in parts if p.strip(" ,;.")]


def to_action(step: str) -> GroundAction | None:
    """The ground action a step names, or None for the final "done"."""
    if step in ("done", "i'm done", "i am done"):
        return None
    for pattern, name in PATTERNS:
        m = pattern.match(step)
        if m:
            return GroundAction(name, m.groups())
    raise NoPlanError(f"the model's step {step!r} names no Blocksworld action")


def plan(problem: Problem, time_limit: float | None) -> list[GroundAction]:
    """The actions of the model's answer for ``problem`` (``time_limit`` is not needed)."""
    path = ANSWERS / f"{problem.name}.txt"
    if not path.is_file():
        raise InputError(f"{path}: no answer from the language model for problem {problem.name}")
    actions = [to_action(s) for s in steps(path.read_text(encoding="utf-8"))]
    return [a for a in actions if a is not None]
