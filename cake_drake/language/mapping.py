"""Map transcript steps onto a PDDL problem and simulate them.

Each step gets a verdict:

- ``maps cleanly``: one skill, one ground action, applicable;
- ``maps to several actions``: one skill, several ground actions (a decomposition
  the language model did implicitly; an HTN method would state it);
- ``precondition fails``: the action is not applicable; the unmet facts are named;
- ``no schema``: the verb or an object is not in the lexicon / domain / problem;
- ``done``: the end marker; ``not reached``: after a step that failed;
  ``after done``: steps written after the end marker (ignored).
"""

from __future__ import annotations

import difflib
import itertools
import re
from dataclasses import dataclass, field

from cake_drake.errors import CakeDrakeError
from cake_drake.language.lexicon import (
    ARTICLES,
    END_PHRASES,
    GLOSSES,
    NOUN_ALIASES,
    PRONOUNS,
    VERBS,
    MethodStep,
    Verb,
    verb_vocabulary,
)
from cake_drake.language.transcript import Step, Transcript
from cake_drake.symbolic import (
    Fact,
    GroundAction,
    Plan,
    Problem,
    fact_str,
    solve_problem,
    validate_plan,
)
from cake_drake.symbolic.grounding import ground_action

MAPS_CLEANLY = "maps cleanly"
MAPS_TO_SEVERAL = "maps to several actions"
PRECONDITION_FAILS = "precondition fails"
NO_SCHEMA = "no schema"
DONE = "done"
NOT_REACHED = "not reached"
AFTER_DONE = "after done"

#: Verdicts of steps that were carried out.
GOOD_VERDICTS = (MAPS_CLEANLY, MAPS_TO_SEVERAL, DONE)

_MAX_BINDINGS = 20000
_PARTICLES = {"up", "down", "on", "off", "away", "in", "out", "over", "back", "to", "for"}


@dataclass(frozen=True)
class StepResult:
    """The verdict for one transcript step, with the ground actions it became."""

    step: Step
    verdict: str
    skill: str | None = None
    actions: tuple[GroundAction, ...] = ()
    detail: str = ""
    unmet: tuple[Fact, ...] = ()


@dataclass(frozen=True)
class Analysis:
    """Everything the tool found for one transcript against one problem."""

    transcript: Transcript
    problem: Problem
    steps: tuple[StepResult, ...]
    actions: tuple[GroundAction, ...]  # the transcribed plan, up to the first failing action
    executable: bool
    final_state: frozenset[Fact]
    unmet_goals: tuple[Fact, ...] = ()
    planner_plan: Plan | None = None
    planner_error: str | None = None
    notes: tuple[str, ...] = field(default=())

    @property
    def goal_checked(self) -> bool:
        return self.problem.has_goal and self.executable

    @property
    def ok(self) -> bool:
        """Every step maps and applies, and the goal (if the problem has one) is reached."""
        return self.executable and not self.unmet_goals


class _NoSchema(Exception):
    pass


# ----------------------------------------------------------------------- the lexicon


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


def resolve_noun(phrase: str, problem: Problem, last: str | None) -> str:
    """The problem object a noun phrase names; :class:`_NoSchema` naming the vocabulary."""
    words = phrase.split()
    while words and words[0] in ARTICLES:
        words = words[1:]
    p = " ".join(words)
    if p in PRONOUNS:
        if last is None:
            raise _NoSchema(f"'{phrase}' refers to nothing mentioned before")
        return last
    objects = problem.object_types
    by_name = {o.replace("-", " "): o for o in objects} | {o: o for o in objects}
    tries = [p] + ([p[:-1]] if p.endswith("s") else []) + ([p[:-2]] if p.endswith("es") else [])
    for t in tries:
        if t in by_name:
            return by_name[t]
        if t in NOUN_ALIASES and NOUN_ALIASES[t] in objects:
            return NOUN_ALIASES[t]
    raise _NoSchema(
        f"'{p or phrase}' is not an object of problem '{problem.name}' "
        f"(objects: {_listing(sorted(objects))})"
    )


# ----------------------------------------------------------------------- binding


def _place_of(problem: Problem, state: frozenset[Fact], obj: str, want: str) -> str | None:
    """Where ``obj`` is: the unique object of type ``want`` it stands at in ``state``."""
    domain = problem.domain
    places = {
        f[2]
        for f in state
        if len(f) == 3
        and f[1] == obj
        and f[2] in problem.object_types
        and domain.is_subtype(problem.object_types[f[2]], want)
    }
    return places.pop() if len(places) == 1 else None


def _bind(
    problem: Problem, state: frozenset[Fact], ms: MethodStep, slots: dict[str, str]
) -> tuple[GroundAction, frozenset[Fact], list[str]]:
    """Ground one method step in ``state``: (action, unmet preconditions, notes)."""
    domain = problem.domain
    schema = domain.actions.get(ms.schema)
    if schema is None:
        raise _NoSchema(
            f"domain '{domain.name}' has no action '{ms.schema}' "
            f"(actions: {', '.join(sorted(domain.actions))})"
        )
    types = dict(schema.params)
    fixed: dict[str, str] = {}
    notes: list[str] = []
    for param, source in ms.args:
        if param not in types:
            raise _NoSchema(f"action {schema.signature()} has no parameter {param}")
        obj = slots.get(source, source)
        if obj not in problem.object_types:
            raise _NoSchema(
                f"'{obj}' is not an object of problem '{problem.name}' "
                f"(objects: {_listing(sorted(problem.object_types))})"
            )
        want, have = types[param], problem.object_types[obj]
        if domain.is_subtype(have, want):
            fixed[param] = obj
            continue
        place = _place_of(problem, state, obj, want)
        if place is None:
            raise _NoSchema(
                f"'{obj}' has type '{have}' but {param} of {schema.signature()} needs type '{want}'"
            )
        fixed[param] = place
        notes.append(f"'{obj}' read as its place, {place}")
    free = [(p, t) for p, t in schema.params if p not in fixed]
    choices = [problem.objects_of_type(t) for _, t in free]
    count = 1
    for c in choices:
        count *= len(c)
    if count == 0:
        raise _NoSchema(f"no objects of the types {schema.signature()} needs")
    if count > _MAX_BINDINGS:
        raise _NoSchema(f"{schema.signature()} has {count} ways to fill its free parameters")
    named = set(fixed.values())
    best = None
    for combo in itertools.product(*choices):
        binding = fixed | dict(zip((p for p, _ in free), combo, strict=True))
        action = GroundAction(schema.name, tuple(binding[p] for p, _ in schema.params))
        unmet = ground_action(problem, action).pre - state
        about_named = sum(1 for f in unmet if named & set(f[1:]))
        key = (about_named, len(unmet))
        if best is None or key < best[0]:
            best = (key, action, unmet)
            if not unmet:
                break
    assert best is not None
    return best[1], frozenset(best[2]), notes


def gloss(fact: Fact) -> str:
    """An unmet fact in plain words, e.g. ``top-drawer is not open``."""
    template = GLOSSES.get(fact[0])
    if template is None or template.count("{") > len(fact) - 1:
        return f"{fact_str(fact)} is false"
    text = template.format(*fact[1:])
    return "the " + text if text.startswith("robot ") else text


def _try_method(problem, state, method, slots):
    """Apply a method's steps in turn: (actions, state, unmet, notes) or _NoSchema."""
    actions: list[GroundAction] = []
    notes: list[str] = []
    for ms in method:
        action, unmet, more = _bind(problem, state, ms, slots)
        actions.append(action)
        notes += more
        if unmet:
            return actions, state, unmet, notes
        op = ground_action(problem, action)
        state = op.apply(state)
    return actions, state, frozenset(), notes


def map_step(
    problem: Problem, state: frozenset[Fact], step: Step, last: str | None
) -> tuple[StepResult, frozenset[Fact], str | None]:
    """Verdict for one step in ``state``: (result, next state, last object mentioned)."""
    if step.text in END_PHRASES:
        return StepResult(step, DONE, "done", detail="end of the robot's plan"), state, last
    if not step.text:
        return StepResult(step, NO_SCHEMA, detail="the step is empty"), state, last
    matched = match_verb(step.text)
    if matched is None:
        return StepResult(step, NO_SCHEMA, detail=unknown_verb_message(step.text)), state, last
    verb, phrases = matched
    try:
        slots = {k: resolve_noun(v, problem, last) for k, v in phrases.items()}
    except _NoSchema as e:
        return StepResult(step, NO_SCHEMA, verb.skill, detail=str(e)), state, last
    last = slots.get("x", last)
    failures = []
    for method in verb.methods:
        try:
            actions, new_state, unmet, notes = _try_method(problem, state, method, slots)
        except _NoSchema as e:
            failures.append((1, 0, StepResult(step, NO_SCHEMA, verb.skill, detail=str(e))))
            continue
        if not unmet:
            verdict = MAPS_CLEANLY if len(actions) == 1 else MAPS_TO_SEVERAL
            detail = "; ".join(notes)
            if len(actions) > 1:
                detail = "; ".join(
                    [f"one skill, {len(actions)} actions (an implicit decomposition)", *notes]
                )
            return StepResult(step, verdict, verb.skill, tuple(actions), detail), new_state, last
        unmet_sorted = tuple(sorted(unmet))
        detail = "unmet " + ", ".join(f"{fact_str(f)}: {gloss(f)}" for f in unmet_sorted)
        if notes:
            detail += "; " + "; ".join(notes)
        result = StepResult(
            step, PRECONDITION_FAILS, verb.skill, tuple(actions), detail, unmet_sorted
        )
        failures.append((0, len(unmet), result))
    failures.sort(key=lambda f: (f[0], f[1]))
    return failures[0][2], state, last


def lexical_verdict(
    problem: Problem, step: Step, last: str | None
) -> tuple[str | None, str | None]:
    """For steps that are not simulated: a no-schema reason found without a state, if any."""
    if step.text in END_PHRASES:
        return None, last
    if not step.text:
        return "the step is empty", last
    matched = match_verb(step.text)
    if matched is None:
        return unknown_verb_message(step.text), last
    _, phrases = matched
    try:
        slots = {k: resolve_noun(v, problem, last) for k, v in phrases.items()}
    except _NoSchema as e:
        return str(e), last
    return None, slots.get("x", last)


# ----------------------------------------------------------------------- the whole transcript


def analyse(
    transcript: Transcript,
    problem: Problem,
    planner: str | None = "astar-lmcut",
    time_limit: float | None = 30.0,
) -> Analysis:
    """Map and simulate every step, check the goal, and plan the same problem."""
    state = problem.init
    results: list[StepResult] = []
    actions: list[GroundAction] = []
    last: str | None = None
    failed = False
    ended = False
    for step in transcript.steps:
        if ended:
            results.append(StepResult(step, AFTER_DONE, detail="written after 'done'; ignored"))
            continue
        if failed:
            reason, last = lexical_verdict(problem, step, last)
            if reason is not None:
                results.append(StepResult(step, NO_SCHEMA, detail=reason))
            elif step.text in END_PHRASES:
                results.append(StepResult(step, DONE, "done", detail="end of the robot's plan"))
                ended = True
            else:
                results.append(StepResult(step, NOT_REACHED, detail="an earlier step failed"))
            continue
        result, state, last = map_step(problem, state, step, last)
        results.append(result)
        actions.extend(result.actions)
        if result.verdict == DONE:
            ended = True
        elif result.verdict not in GOOD_VERDICTS:
            failed = True

    notes = list(transcript.notes)
    if not ended:
        notes.append("the transcript has no final 'done' step")
    executable = not failed
    unmet_goals: tuple[Fact, ...] = ()
    if executable:
        check = validate_plan(problem, actions)
        if not check.ok and check.reason != "goal":  # mapping and validator disagree: a bug
            raise CakeDrakeError(f"internal: the transcribed plan does not validate: {check}")
        unmet_goals = check.unmet_goals

    planned, planner_error = None, None
    if planner is not None and problem.has_goal:
        try:
            planned = solve_problem(problem, planner, time_limit)
        except CakeDrakeError as e:
            planner_error = str(e)
    return Analysis(
        transcript,
        problem,
        tuple(results),
        tuple(actions),
        executable,
        state,
        unmet_goals,
        planned,
        planner_error,
        tuple(notes),
    )


def side_by_side(
    left: tuple[GroundAction, ...], right: tuple[GroundAction, ...]
) -> list[tuple[str, str, str]]:
    """Align two plans: rows of (marker, left, right); '=' same, '~' differs, '<' / '>' only one."""
    a, b = [str(x) for x in left], [str(x) for x in right]
    rows: list[tuple[str, str, str]] = []
    matcher = difflib.SequenceMatcher(None, a, b, autojunk=False)
    for tag, i1, i2, j1, j2 in matcher.get_opcodes():
        if tag == "equal":
            rows += [("=", a[i], b[j]) for i, j in zip(range(i1, i2), range(j1, j2), strict=True)]
            continue
        n = max(i2 - i1, j2 - j1)
        for k in range(n):
            la = a[i1 + k] if i1 + k < i2 else ""
            rb = b[j1 + k] if j1 + k < j2 else ""
            rows.append(("~" if la and rb else "<" if la else ">", la, rb))
    return rows
