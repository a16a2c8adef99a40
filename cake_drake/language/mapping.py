"""Map transcript steps onto a PDDL problem and simulate them.

Each step gets a verdict:

- ``maps cleanly``: the words' literal reading, one ground action, applicable;
- ``maps via a method``: one action, but not the one the words name literally --
  the state chose it (an HTN method: "put down X" where an open container stands
  is ``put-in``); the method and the reason are reported;
- ``maps to several actions``: one skill, several ground actions (a decomposition
  the language model did implicitly; the method is reported);
- ``precondition fails``: the action is not applicable; the unmet facts are named;
- ``ambiguous``: a noun names several objects ("the counter"), or a method applies
  in several ways; the candidates are listed;
- ``no schema``: the verb or an object is not in the lexicon / domain / problem;
- ``done``: the end marker; ``not reached``: after a step that failed;
  ``after done``: steps written after the end marker (ignored).

How a step's words are read (its skill phrase, the objects its nouns name) is
:mod:`.reading`; ``--add-objects`` is :mod:`.objects`.
"""

from __future__ import annotations

import difflib
import itertools
import re
from dataclasses import dataclass, field

from cake_drake.errors import CakeDrakeError, InputError
from cake_drake.language.lexicon import END_PHRASES, GLOSSES, Verb
from cake_drake.language.methods import Method, MethodStep, explain, method_bindings
from cake_drake.language.objects import _where_predicates
from cake_drake.language.reading import (
    _Ambiguous,
    _leading_verb,
    _listing,
    _NoSchema,
    _Reference,
    _resolve_slots,
    _spaced,
    match_verb,
    unknown_verb_message,
)
from cake_drake.language.transcript import Step, Transcript
from cake_drake.symbolic import (
    Fact,
    GroundAction,
    Plan,
    Problem,
    fact_str,
    parse_problem,
    solve_problem,
    validate_plan,
)
from cake_drake.symbolic.grounding import ground_action

MAPS_CLEANLY = "maps cleanly"
MAPS_VIA_METHOD = "maps via a method"
MAPS_TO_SEVERAL = "maps to several actions"
PRECONDITION_FAILS = "precondition fails"
AMBIGUOUS = "ambiguous"
NO_SCHEMA = "no schema"
DONE = "done"
NOT_REACHED = "not reached"
AFTER_DONE = "after done"

#: Verdicts of steps that were carried out.
GOOD_VERDICTS = (MAPS_CLEANLY, MAPS_VIA_METHOD, MAPS_TO_SEVERAL, DONE)
#: Verdicts of skill steps, in the order summaries list them.
SKILL_VERDICTS = (
    MAPS_CLEANLY,
    MAPS_VIA_METHOD,
    MAPS_TO_SEVERAL,
    PRECONDITION_FAILS,
    AMBIGUOUS,
    NO_SCHEMA,
    NOT_REACHED,
)

_MAX_BINDINGS = 20000


@dataclass(frozen=True)
class StepResult:
    """The verdict for one transcript step, with the ground actions it became.

    ``actions`` are all the step's actions; when ``failed`` the last of them is the
    one whose precondition fails (it was not applied). ``method`` is the method
    that fired and ``why`` the reason, in words. ``need`` says what would have made
    the step map cleanly (empty when it did).
    """

    step: Step
    verdict: str
    skill: str | None = None
    actions: tuple[GroundAction, ...] = ()
    detail: str = ""
    unmet: tuple[Fact, ...] = ()
    method: Method | None = None
    why: str = ""
    failed: bool = False
    candidates: tuple[str, ...] = ()
    need: str = ""
    resolved: tuple[tuple[str, str], ...] = ()  # (noun phrase, object) as read
    unplaced: tuple[str, ...] = ()  # objects the state places nowhere (see map_step)

    @property
    def applied(self) -> tuple[GroundAction, ...]:
        """The actions that were carried out."""
        return self.actions[:-1] if self.failed else self.actions


@dataclass(frozen=True)
class Analysis:
    """Everything the tool found for one transcript against one problem."""

    transcript: Transcript
    problem: Problem
    steps: tuple[StepResult, ...]
    actions: tuple[GroundAction, ...]  # the transcribed plan's applied actions
    executable: bool
    final_state: frozenset[Fact]
    unmet_goals: tuple[Fact, ...] = ()
    planner_plan: Plan | None = None
    planner_error: str | None = None
    notes: tuple[str, ...] = field(default=())
    failed_action: GroundAction | None = None  # the first action that is not applicable
    goal_from_transcript: bool = False

    @property
    def goal_checked(self) -> bool:
        return self.problem.has_goal and self.executable

    @property
    def ok(self) -> bool:
        """Every step maps and applies, and the goal (if the problem has one) is reached."""
        return self.executable and not self.unmet_goals

    @property
    def plan_actions(self) -> tuple[GroundAction, ...]:
        """The transcribed plan as written: applied actions, then the failing one if any."""
        return self.actions + ((self.failed_action,) if self.failed_action else ())


class _GoalNotInProblem(Exception):
    """The transcript's goal names objects the problem lacks (a note, not bad input)."""


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
    problem: Problem, state: frozenset[Fact], ms: MethodStep, values: dict[str, str]
) -> tuple[GroundAction, frozenset[Fact], list[str]]:
    """Ground one method step in ``state``: (action, unmet preconditions, notes).

    ``values`` holds the noun slots (``x``, ``y``) and the method's variables (``?c``).
    """
    domain = problem.domain
    schema = domain.actions.get(ms.schema)
    if schema is None:
        raise _NoSchema(
            f"domain '{domain.name}' has no action '{ms.schema}' "
            f"(actions: {', '.join(sorted(domain.actions))})",
            need=f"an action schema '{ms.schema}' in the domain",
        )
    types = dict(schema.params)
    fixed: dict[str, str] = {}
    notes: list[str] = []
    for param, source in ms.args:
        if param not in types:
            raise _NoSchema(f"action {schema.signature()} has no parameter {param}")
        if source.startswith("?") and source not in values:
            continue  # an unbound method variable: bound from the state below
        obj = values.get(source, source)
        if obj not in problem.object_types:
            raise _NoSchema(
                f"'{obj}' is not an object of problem '{problem.name}' "
                f"(objects: {_listing(sorted(problem.object_types))})",
                need=f"'{obj}' among the problem's objects",
            )
        want, have = types[param], problem.object_types[obj]
        if domain.is_subtype(have, want):
            fixed[param] = obj
            continue
        place = _place_of(problem, state, obj, want)
        if place is None:
            raise _NoSchema(
                f"'{obj}' has type '{have}' but {param} of {schema.signature()} "
                f"needs type '{want}'",
                need=f"a reading of a {have} where {schema.name} needs a {want}",
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


def assumed(fact: Fact) -> str:
    """What a plan took for granted, in plain words: ``the robot is at far-counter``."""
    return gloss(fact).replace(" is not ", " is ").replace("cannot", "can")


def _try_method(problem, state, method: Method, values: dict[str, str]):
    """Apply a method's actions in turn: (actions, state, unmet, notes) or _NoSchema."""
    actions: list[GroundAction] = []
    notes: list[str] = []
    for ms in method.steps:
        action, unmet, more = _bind(problem, state, ms, values)
        actions.append(action)
        notes += more
        if unmet:
            return actions, state, unmet, notes
        state = ground_action(problem, action).apply(state)
    return actions, state, frozenset(), notes


def choose_method(
    verb: Verb, state: frozenset[Fact], slots: dict[str, str]
) -> tuple[Method, list[dict[str, str]]]:
    """The first of the skill's methods whose precondition holds, with its bindings."""
    for method in verb.methods:
        bindings = method_bindings(method, state, slots)
        if bindings:
            return method, bindings
    # No method applies (a skill without a literal reading): report the last one.
    return verb.methods[-1], []


def map_step(
    problem: Problem,
    state: frozenset[Fact],
    step: Step,
    ref: _Reference,
    request: str = "",
) -> tuple[StepResult, frozenset[Fact]]:
    """Verdict for one step in ``state``: (result, next state); ``ref`` is updated."""
    if step.text in END_PHRASES:
        return StepResult(step, DONE, "done", detail="end of the robot's plan"), state
    if not step.text:
        return StepResult(step, NO_SCHEMA, detail="the step is empty"), state
    matched = match_verb(step.text)
    if matched is None:
        msg = unknown_verb_message(step.text)
        need = f"a skill and action schema for '{_leading_verb(step.text)}'"
        return StepResult(step, NO_SCHEMA, detail=msg, need=need), state
    verb, phrases = matched
    try:
        slots = _resolve_slots(verb, phrases, problem, ref, request, step.number)
    except _Ambiguous as e:
        result = StepResult(
            step, AMBIGUOUS, verb.skill, detail=str(e), candidates=e.candidates, need=e.need
        )
        return result, state
    except _NoSchema as e:
        return StepResult(step, NO_SCHEMA, verb.skill, detail=str(e), need=e.need), state
    resolved = tuple((phrases[k], slots[k]) for k in sorted(slots))
    method, bindings = choose_method(verb, state, slots)
    if len(bindings) > 1:
        ways = "; ".join(", ".join(f"{k}={v}" for k, v in sorted(b.items())) for b in bindings)
        varying = [k for k in bindings[0] if len({b[k] for b in bindings}) > 1]
        cands = tuple(sorted({b[k] for b in bindings for k in varying}))
        return (
            StepResult(
                step,
                AMBIGUOUS,
                verb.skill,
                detail=f"method {method.name} applies in {len(bindings)} ways ({ways})",
                method=method,
                candidates=cands,
                need="a choice between " + " and ".join(cands),
                resolved=resolved,
            ),
            state,
        )
    binding = bindings[0] if bindings else {}
    why = explain(method, slots, binding) if not method.literal else ""
    try:
        actions, new_state, unmet, notes = _try_method(problem, state, method, slots | binding)
    except _NoSchema as e:
        result = StepResult(
            step,
            NO_SCHEMA,
            verb.skill,
            detail=str(e),
            method=method,
            need=e.need,
            resolved=resolved,
        )
        return result, state
    if not unmet:
        if len(actions) > 1:
            verdict = MAPS_TO_SEVERAL
            need = f"'{verb.skill}' = {' + '.join(a.name for a in actions)} when {why}"
        elif method.literal:
            verdict, need = MAPS_CLEANLY, ""
        else:
            verdict = MAPS_VIA_METHOD
            need = f"'{verb.skill}' = {actions[0].name} when {why}"
        parts = ([f"method {method.name}: {why}"] if why else []) + notes
        result = StepResult(
            step,
            verdict,
            verb.skill,
            tuple(actions),
            "; ".join(parts),
            method=method,
            why=why,
            need=need,
            resolved=resolved,
        )
        return result, new_state
    unmet_sorted = tuple(sorted(unmet))
    need = ", ".join(assumed(f) for f in unmet_sorted)
    unplaced = _unplaced(problem, state, actions[-1], unmet_sorted)
    if unplaced:
        # Where the item is was never said, by the problem or by the transcript: the place
        # in the action is only the binding tried, so nothing here is the model's assumption.
        need = ", ".join(
            f"a place for {o} (no fact of the problem says where it is)" for o in unplaced
        )
    for f in unmet_sorted:
        if f[0] == "at-location" and f[1] == "robot":
            here = [a for a in actions[-1].args if ("at-location", a, f[2]) in state]
            if here:
                need += f" (a 'find {_spaced(here[0])}' step would have taken it there)"
    detail = "unmet " + ", ".join(f"{fact_str(f)}: {gloss(f)}" for f in unmet_sorted)
    if why:
        detail = f"method {method.name}: {why}; " + detail
    if notes:
        detail += "; " + "; ".join(notes)
    if unplaced:
        detail += "; " + ", ".join(f"no fact says where {o} is" for o in unplaced)
    result = StepResult(
        step,
        PRECONDITION_FAILS,
        verb.skill,
        tuple(actions),
        detail,
        unmet_sorted,
        method=method,
        why=why,
        failed=True,
        need=need,
        resolved=resolved,
        unplaced=unplaced,
    )
    return result, state


def _unplaced(
    problem: Problem, state: frozenset[Fact], action: GroundAction, unmet: tuple[Fact, ...]
) -> tuple[str, ...]:
    """The arguments of ``action`` that an unmet fact wants somewhere and that ``state``
    places nowhere: no fact says where they are, none holds or contains them."""
    statics = problem.domain.static_predicates
    out = []
    for obj in dict.fromkeys(action.args):
        where = _where_predicates(problem, problem.object_types[obj])
        if not any(f[0] in where and f[1] == obj for f in unmet):
            continue
        if any(obj in f[1:] and (f[0] in where or f[0] not in statics) for f in state):
            continue
        out.append(obj)
    return tuple(out)


def lexical_verdict(
    problem: Problem, step: Step, ref: _Reference, request: str = ""
) -> StepResult | None:
    """For steps that are not simulated: a no-schema or ambiguity found without a state."""
    if step.text in END_PHRASES:
        return None
    if not step.text:
        return StepResult(step, NO_SCHEMA, detail="the step is empty")
    matched = match_verb(step.text)
    if matched is None:
        need = f"a skill and action schema for '{_leading_verb(step.text)}'"
        return StepResult(step, NO_SCHEMA, detail=unknown_verb_message(step.text), need=need)
    verb, phrases = matched
    try:
        _resolve_slots(verb, phrases, problem, ref, request, step.number)
    except _Ambiguous as e:
        return StepResult(
            step, AMBIGUOUS, verb.skill, detail=str(e), candidates=e.candidates, need=e.need
        )
    except _NoSchema as e:
        return StepResult(step, NO_SCHEMA, verb.skill, detail=str(e), need=e.need)
    return None


# ----------------------------------------------------------------------- goals


def problem_with_goal(problem: Problem, transcript: Transcript) -> Problem:
    """``problem`` with the transcript's ``Goal:`` added (the problem must have none)."""
    goal = transcript.goal
    assert goal is not None and not problem.has_goal
    text = problem.text.rstrip()
    if not text.endswith(")"):
        raise InputError(f"{problem.problem_path}: cannot add a goal to this problem text")
    body = goal if goal.lstrip().startswith("(") else f"({goal})"
    composed = f"{text[:-1]}\n  (:goal {body}))\n"
    where = f"{transcript.source}:{transcript.goal_line}"
    predicates = set(problem.domain.predicates) | {"and", "not"}
    heads = set(re.findall(r"\(\s*([^()\s]+)", body.lower()))
    unknown = sorted(heads - predicates)
    if unknown:
        raise InputError(
            f"{where}: Goal: {goal}: unknown predicate {', '.join(unknown)}; the domain's "
            f"predicates are {', '.join(sorted(problem.domain.predicates))}"
        )
    names = set(re.findall(r"[a-z][a-z0-9_-]*", goal.lower())) - predicates - heads
    missing = sorted(n for n in names if n not in problem.object_types)
    if missing and all(re.fullmatch(r"[a-z][a-z0-9_-]*", n) for n in missing):
        raise _GoalNotInProblem(
            f"the transcript's Goal: ({where}) names {', '.join(missing)}, which problem "
            f"'{problem.name}' does not have: the goal is not checked"
        )
    try:
        return parse_problem(problem.domain, composed, problem.problem_path)
    except InputError as e:
        msg = str(e)
        if msg.startswith(problem.problem_path):
            msg = msg.split(": ", 1)[-1]
        raise InputError(f"{where}: Goal: {goal}: {msg}") from None


# ----------------------------------------------------------------------- the whole transcript


def analyse(
    transcript: Transcript,
    problem: Problem,
    planner: str | None = "astar-lmcut",
    time_limit: float | None = 30.0,
) -> Analysis:
    """Map and simulate every step, check the goal, and plan the same problem."""
    notes = list(transcript.notes)
    goal_from_transcript = False
    if transcript.goal is not None:
        if problem.has_goal:
            notes.append(
                f"the problem has a goal; the transcript's Goal: line ({transcript.goal}) "
                "is not used"
            )
        else:
            try:
                problem = problem_with_goal(problem, transcript)
                goal_from_transcript = True
            except _GoalNotInProblem as e:
                notes.append(str(e))
    state = problem.init
    results: list[StepResult] = []
    actions: list[GroundAction] = []
    ref = _Reference()
    failed_action: GroundAction | None = None
    failed = False
    ended = False
    for step in transcript.steps:
        if ended:
            results.append(StepResult(step, AFTER_DONE, detail="written after 'done'; ignored"))
            continue
        if failed:
            lexical = lexical_verdict(problem, step, ref, transcript.request)
            if lexical is not None:
                results.append(lexical)
            elif step.text in END_PHRASES:
                results.append(StepResult(step, DONE, "done", detail="end of the robot's plan"))
                ended = True
            else:
                results.append(StepResult(step, NOT_REACHED, detail="an earlier step failed"))
            continue
        result, state = map_step(problem, state, step, ref, transcript.request)
        results.append(result)
        actions.extend(result.applied)
        if result.failed:
            failed_action = result.actions[-1]
        if result.verdict == DONE:
            ended = True
        elif result.verdict not in GOOD_VERDICTS:
            failed = True

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
        failed_action,
        goal_from_transcript,
    )


def achiever(problem: Problem, plan: tuple[GroundAction, ...], fact: Fact) -> GroundAction | None:
    """The first action of ``plan`` that makes ``fact`` true, if any."""
    for action in plan:
        if fact in ground_action(problem, action).add:
            return action
    return None


def side_by_side(
    left: tuple[GroundAction, ...],
    right: tuple[GroundAction, ...],
    failed: GroundAction | None = None,
) -> list[tuple[str, str, str]]:
    """Align two plans: rows of (marker, left, right).

    ``=`` same action, ``~`` differs, ``<`` / ``>`` only on one side; ``x`` the
    transcript's failing action (not applied, so never matched nor counted), placed
    after the applied actions it follows.
    """
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
    if failed is not None:
        last_left = max((i for i, (_, la, _) in enumerate(rows) if la), default=-1)
        rows.insert(last_left + 1, ("x", str(failed), ""))
    return rows
