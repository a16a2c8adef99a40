"""Rendering an :class:`Analysis`: a terminal table, a Markdown report with its note, files."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from cake_drake.language.mapping import (
    AMBIGUOUS,
    DONE,
    GOOD_VERDICTS,
    MAPS_CLEANLY,
    MAPS_TO_SEVERAL,
    MAPS_VIA_METHOD,
    NO_SCHEMA,
    NOT_REACHED,
    PRECONDITION_FAILS,
    SKILL_VERDICTS,
    Analysis,
    StepResult,
    achiever,
    gloss,
    side_by_side,
)
from cake_drake.symbolic import facts_str


def fluents(analysis: Analysis):
    """The state reached without the facts no action can change."""
    statics = analysis.problem.domain.static_predicates
    return frozenset(f for f in analysis.final_state if f[0] not in statics)


def _actions_text(result: StepResult) -> str:
    parts = [str(a) for a in result.applied]
    if result.failed:
        parts.append(f"{result.actions[-1]} [fails]")
    return " ".join(parts) or "-"


def verdict_summary(analysis: Analysis) -> str:
    """``6 skill steps -- maps cleanly: 4, maps via a method: 2`` (the end marker aside)."""
    counts = Counter(r.verdict for r in analysis.steps)
    parts = [f"{v}: {counts[v]}" for v in SKILL_VERDICTS if counts[v]]
    total = sum(counts[v] for v in SKILL_VERDICTS)
    return f"{total} skill step{'s' * (total != 1)} -- " + (", ".join(parts) or "none")


def outcome(analysis: Analysis) -> str:
    """One line: the verdict on the transcribed plan as a whole."""
    p = analysis.problem
    if not analysis.executable:
        bad = next(r for r in analysis.steps if r.verdict not in GOOD_VERDICTS)
        return f"FAILS at step {bad.step.number} ({bad.verdict}): the transcribed plan stops there"
    if not p.has_goal:
        return (
            f"EXECUTABLE: all {len(analysis.actions)} actions apply in '{p.name}' "
            "(no goal to check: give the transcript a Goal: line)"
        )
    if analysis.unmet_goals:
        return (
            f"GOAL NOT REACHED: all {len(analysis.actions)} actions apply, unmet goals "
            f"{facts_str(analysis.unmet_goals)}"
        )
    return f"VALID: {len(analysis.actions)} actions reach the goal of '{p.name}'"


def _planner_line(analysis: Analysis) -> str:
    if not analysis.problem.has_goal:
        return "planner: not run (the problem has no goal)"
    if analysis.planner_plan is None:
        return f"planner: {analysis.planner_error or 'not run'}"
    return analysis.planner_plan.note()


def _goal_line(analysis: Analysis) -> str | None:
    p = analysis.problem
    if not p.has_goal:
        return None
    where = (
        f"the transcript's Goal: line ({analysis.transcript.source}:"
        f"{analysis.transcript.goal_line})"
        if analysis.goal_from_transcript
        else "the problem"
    )
    return f"goal: {facts_str(sorted(p.goal))} (from {where})"


def _count(analysis: Analysis) -> str:
    n = f"{len(analysis.actions)} actions"
    return n + (" (+1 failed)" if analysis.failed_action else "")


def comparison_rows(analysis: Analysis) -> list[tuple[str, str, str]]:
    """The transcribed plan beside the planner's; the failing action marked ``x``."""
    assert analysis.planner_plan is not None
    return side_by_side(analysis.actions, analysis.planner_plan.actions, analysis.failed_action)


# ----------------------------------------------------------------------- the note


def _quote(r: StepResult) -> str:
    return f'step {r.step.number} "{r.step.text}"'


def _acts(r: StepResult) -> str:
    return " + ".join(f"`{a}`" for a in r.actions)


def _finds_used_as_moves(analysis: Analysis) -> list:
    """The planner's ``find`` actions whose item it never picks up: moves in disguise."""
    plan = analysis.planner_plan.actions if analysis.planner_plan else ()
    handled = {a.args[0] for a in plan if a.name in ("pick-up", "take-out") and a.args}
    return [a for a in plan if a.name == "find" and a.args and a.args[0] not in handled]


def render_note(analysis: Analysis) -> list[str]:
    """The half-page note: what mapped, what did not and why, what would have been needed."""
    steps = analysis.steps
    by = {v: [r for r in steps if r.verdict == v] for v in SKILL_VERDICTS}
    skill_steps = [r for r in steps if r.verdict in SKILL_VERDICTS]
    out = ["## Note", ""]

    # Plan length: SayCan's plans are short; compare with the planner's.
    length = (
        f"**Length.** {len(skill_steps)} skill steps became {len(analysis.plan_actions)} "
        f"PDDL actions"
    )
    if analysis.failed_action:
        length += f" ({len(analysis.actions)} applied, then one that fails)"
    if analysis.planner_plan is not None:
        length += f"; the planner needs {analysis.planner_plan.length} for the same goal"
    out += [length + ".", ""]

    clean = by[MAPS_CLEANLY]
    if clean:
        listed = ", ".join(f"{r.step.number} ({r.skill})" for r in clean)
        out.append(
            f"**Mapped cleanly ({len(clean)}):** steps {listed}: each the literal reading of "
            "its words, one action, with the parameters the words leave out (where the "
            "robot and the item are) bound from the state."
        )
    methods = by[MAPS_VIA_METHOD] + by[MAPS_TO_SEVERAL]
    if methods:
        out += ["", f"**Mapped through a method ({len(methods)}):**", ""]
        for r in sorted(methods, key=lambda r: r.step.number):
            assert r.method is not None
            out.append(
                f"- {_quote(r)} = {_acts(r)}: method `{r.method.name}` fired because "
                f"{r.why}. The words alone do not say this; the state does."
            )
    bad = [r for r in steps if r.verdict in (PRECONDITION_FAILS, AMBIGUOUS, NO_SCHEMA)]
    if bad:
        out += ["", f"**Did not map ({len(bad)}):**", ""]
        for r in bad:
            out.append(f"- {_quote(r)}: {r.verdict} -- {r.detail}.")
        if by[NOT_REACHED]:
            nums = ", ".join(str(r.step.number) for r in by[NOT_REACHED])
            out.append(f"- steps {nums}: not reached (STRIPS stops at the first failure).")
    out.append("")

    # What would have been needed.
    needs: list[str] = []
    for r in sorted(methods, key=lambda r: r.step.number):
        needs.append(f"a method (step {r.step.number}): {r.need}")
    for r in by[PRECONDITION_FAILS]:
        if r.unplaced:  # the problem, not the model, left out where a thing is
            needs.append(f"a fact the problem lacks (step {r.step.number}): {r.need}")
            continue
        line = f"a precondition the language model assumed (step {r.step.number}): {r.need}"
        if analysis.planner_plan is not None:
            fixes = [
                f"`{a}`"
                for f in r.unmet
                if (a := achiever(analysis.problem, analysis.planner_plan.actions, f))
            ]
            if fixes:
                line += f" -- the planner's plan makes it true with {', '.join(fixes)}"
        needs.append(line)
    for r in by[AMBIGUOUS]:
        needs.append(f"a resolved reference (step {r.step.number}): {r.need}")
    for r in by[NO_SCHEMA]:
        needs.append(f"a larger domain (step {r.step.number}): {r.need or r.detail}")
    if any(r.skill == "find" and r.verdict in GOOD_VERDICTS for r in steps):
        line = (
            "a predicate for what *find* achieves: here it is a move to where the item "
            "lies; its real effect, knowing where the item is, needs knowledge predicates "
            "and sensing, which STRIPS does not have"
        )
        moves = _finds_used_as_moves(analysis)
        if moves:
            line += f" (the planner uses {', '.join(f'`{a}`' for a in moves)} only to move)"
        needs.append(line)
    if analysis.unmet_goals:
        needs.append(
            "the steps that reach the rest of the goal: "
            + ", ".join(gloss(f).replace(" is not ", " should be ") for f in analysis.unmet_goals)
        )
    if not analysis.problem.has_goal:
        needs.append(
            "a goal: without one only executability is checked (a `Goal:` line in the "
            "transcript states the request in PDDL)"
        )
    if needs:
        out += ["**What would have been needed:**", ""]
        out += [f"- {n}." for n in needs]
    else:
        out.append("**Nothing was missing:** every step is one literal action and the goal holds.")
    out.append("")
    return out


# ----------------------------------------------------------------------- renderers


def render_text(analysis: Analysis) -> str:
    """The terminal report: per-step table, outcome, plans side by side, the note."""
    t = analysis.transcript
    lines = []
    if t.request:
        lines.append(f"request: {t.request}")
    lines.append(
        f"problem: {analysis.problem.name} ({analysis.problem.problem_path}), "
        f"domain {analysis.problem.domain.name}"
    )
    goal = _goal_line(analysis)
    if goal:
        lines.append(goal)
    lines.append("")
    w_text = max([len(r.step.text) for r in analysis.steps] + [len("step")])
    w_verdict = max(len(r.verdict) for r in analysis.steps)
    lines.append(f"{'#':>3}  {'step':<{w_text}}  {'verdict':<{w_verdict}}  PDDL / detail")
    for r in analysis.steps:
        head = f"{r.step.number:>3}  {r.step.text:<{w_text}}  {r.verdict:<{w_verdict}}  "
        body = _actions_text(r) if r.actions else ""
        detail = r.detail
        lines.append(head + (body + ("  -- " + detail if detail else "") if body else detail))
    lines.append("")
    lines.append(verdict_summary(analysis))
    for note in analysis.notes:
        lines.append(f"note: {note}")
    lines.append(outcome(analysis))
    lines.append(_planner_line(analysis))
    if analysis.planner_plan is not None:
        rows = comparison_rows(analysis)
        wl = max([len(a) for _, a, _ in rows] + [len("transcribed")])
        lines.append("")
        lines.append(f"    {'transcribed':<{wl}}   planner ({analysis.planner_plan.planner})")
        for mark, a, b in rows:
            lines.append(f"  {mark} {a:<{wl}}   {b}".rstrip())
        lines.append(f"    {_count(analysis):<{wl}}   {analysis.planner_plan.length} actions")
    lines.append(f"state reached (static facts left out): {facts_str(fluents(analysis))}")
    lines.append("")
    lines += [line.replace("**", "").replace("`", "") for line in render_note(analysis)]
    while lines and not lines[-1]:
        lines.pop()
    return "\n".join(lines) + "\n"


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|")


def render_markdown(analysis: Analysis) -> str:
    """The Markdown report written to ``--out``; it ends with the note."""
    t = analysis.transcript
    p = analysis.problem
    out = [f"# Language plan vs PDDL: {Path(t.source).name}", ""]
    if t.request:
        out += [f"**Request:** {_md_escape(t.request)}", ""]
    out += [f"Problem `{p.name}` ({p.problem_path}), domain `{p.domain.name}` ({p.domain_path})."]
    goal = _goal_line(analysis)
    if goal:
        out += ["", f"{goal[0].upper()}{goal[1:]}."]
    out += [
        "",
        "| # | transcript step | verdict | PDDL action(s) | detail |",
        "|---|---|---|---|---|",
    ]
    for r in analysis.steps:
        acts = [f"`{a}`" for a in r.applied]
        if r.failed:
            acts.append(f"`{r.actions[-1]}` (fails)")
        out.append(
            f"| {r.step.number} | {_md_escape(r.step.text)} | {r.verdict} | "
            f"{'<br>'.join(acts) or '-'} | {_md_escape(r.detail)} |"
        )
    out += ["", verdict_summary(analysis) + ".", ""]
    out += [f"- note: {_md_escape(n)}" for n in analysis.notes]
    if analysis.notes:
        out.append("")
    out += [f"**Outcome:** {outcome(analysis)}", "", f"**Planner:** {_planner_line(analysis)}", ""]
    if analysis.planner_plan is not None:
        out += [
            "## Transcribed plan vs planner plan",
            "",
            "`=` same action, `~` different action, `<` only in the transcript, "
            "`>` only in the planner's plan, `x` the transcript's action that fails "
            "(not applied, not counted).",
            "",
            f"| | transcribed ({_count(analysis)}) | "
            f"{analysis.planner_plan.planner} ({analysis.planner_plan.length}) |",
            "|---|---|---|",
        ]
        for mark, a, b in comparison_rows(analysis):
            out.append(f"| {mark} | {f'`{a}`' if a else ''} | {f'`{b}`' if b else ''} |")
        out.append("")
    out += ["## State reached (static facts left out)", "", "```"]
    out += [facts_str(fluents(analysis)), "```", ""]
    out += [_md_escape(line) if line.startswith("- ") else line for line in render_note(analysis)]
    return "\n".join(out)


#: The files a SayCan analysis writes.
SAYCAN_OUTPUTS = ("plan.txt", "problem.pddl", "report.md")


def write_outputs(analysis: Analysis, out_dir: Path, inputs: Sequence = ()) -> list[Path]:
    """Write ``plan.txt`` (transcribed PDDL plan), ``problem.pddl`` and ``report.md``.

    ``plan.txt`` holds the applied actions and, when a step failed, the failing
    action last, so that ``python -m cake_drake.validate`` finds the same failure.
    ``problem.pddl`` includes the transcript's goal when it supplied one.
    """
    from cake_drake.outputs.files import OutputDir

    with OutputDir(out_dir, "saycan", SAYCAN_OUTPUTS, inputs) as staged:
        lines = [str(a) for a in analysis.plan_actions]
        lines.append(f"; cost = {len(analysis.plan_actions)} (unit cost)")
        lines.append(f"; transcribed from {analysis.transcript.source} by cake_drake.saycan")
        if analysis.failed_action:
            lines.append(f"; the last action, {analysis.failed_action}, is not applicable")
        lines.append(f"; {outcome(analysis)}")
        staged.write_text("plan.txt", "\n".join(lines) + "\n")
        staged.write_text("problem.pddl", analysis.problem.text)
        staged.write_text("report.md", render_markdown(analysis))
        return staged.commit()


__all__ = [
    "DONE",
    "comparison_rows",
    "fluents",
    "outcome",
    "render_markdown",
    "render_note",
    "render_text",
    "verdict_summary",
    "write_outputs",
    "SAYCAN_OUTPUTS",
]
