"""Rendering an :class:`Analysis`: a terminal table, a Markdown report, output files."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from cake_drake.errors import InputError
from cake_drake.language.mapping import (
    GOOD_VERDICTS,
    MAPS_CLEANLY,
    MAPS_TO_SEVERAL,
    NO_SCHEMA,
    NOT_REACHED,
    PRECONDITION_FAILS,
    Analysis,
    side_by_side,
)
from cake_drake.symbolic import facts_str


def fluents(analysis: Analysis):
    """The state reached without the facts no action can change."""
    statics = analysis.problem.domain.static_predicates
    return frozenset(f for f in analysis.final_state if f[0] not in statics)


def _actions_text(result) -> str:
    return " ".join(str(a) for a in result.actions) or "-"


def verdict_summary(analysis: Analysis) -> str:
    """``6 skill steps -- maps cleanly: 4, maps to several actions: 2`` (the end marker aside)."""
    counts = Counter(r.verdict for r in analysis.steps)
    order = [MAPS_CLEANLY, MAPS_TO_SEVERAL, PRECONDITION_FAILS, NO_SCHEMA, NOT_REACHED]
    parts = [f"{v}: {counts[v]}" for v in order if counts[v]]
    total = sum(counts[v] for v in order)
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
            "(this problem has no goal to check)"
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


def render_text(analysis: Analysis) -> str:
    """The terminal report: per-step table, outcome, plans side by side."""
    t = analysis.transcript
    lines = []
    if t.request:
        lines.append(f"request: {t.request}")
    lines.append(
        f"problem: {analysis.problem.name} ({analysis.problem.problem_path}), "
        f"domain {analysis.problem.domain.name}"
    )
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
        rows = side_by_side(analysis.actions, analysis.planner_plan.actions)
        wl = max([len(a) for _, a, _ in rows] + [len("transcribed")])
        lines.append("")
        lines.append(f"    {'transcribed':<{wl}}   planner ({analysis.planner_plan.planner})")
        for mark, a, b in rows:
            lines.append(f"  {mark} {a:<{wl}}   {b}")
        total = f"{len(analysis.actions)} actions"
        lines.append(f"    {total:<{wl}}   {analysis.planner_plan.length} actions")
    lines.append(f"state reached (static facts left out): {facts_str(fluents(analysis))}")
    return "\n".join(lines) + "\n"


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|")


def render_markdown(analysis: Analysis) -> str:
    """The Markdown report written to ``--out``."""
    t = analysis.transcript
    p = analysis.problem
    out = [f"# Language plan vs PDDL: {Path(t.source).name}", ""]
    if t.request:
        out += [f"**Request:** {_md_escape(t.request)}", ""]
    out += [
        f"Problem `{p.name}` ({p.problem_path}), domain `{p.domain.name}` ({p.domain_path}).",
        "",
        "| # | transcript step | verdict | PDDL action(s) | detail |",
        "|---|---|---|---|---|",
    ]
    for r in analysis.steps:
        actions = "<br>".join(f"`{a}`" for a in r.actions) or "-"
        out.append(
            f"| {r.step.number} | {_md_escape(r.step.text)} | {r.verdict} | {actions} | "
            f"{_md_escape(r.detail)} |"
        )
    out += ["", verdict_summary(analysis) + ".", ""]
    out += [f"- note: {_md_escape(n)}" for n in analysis.notes]
    out += [f"**Outcome:** {outcome(analysis)}", "", f"**Planner:** {_planner_line(analysis)}", ""]
    if analysis.planner_plan is not None:
        out += [
            "## Transcribed plan vs planner plan",
            "",
            "`=` same action, `~` different action, `<` only in the transcript, "
            "`>` only in the planner's plan.",
            "",
            f"| | transcribed ({len(analysis.actions)}) | "
            f"{analysis.planner_plan.planner} ({analysis.planner_plan.length}) |",
            "|---|---|---|",
        ]
        for mark, a, b in side_by_side(analysis.actions, analysis.planner_plan.actions):
            out.append(f"| {mark} | {f'`{a}`' if a else ''} | {f'`{b}`' if b else ''} |")
        out.append("")
    out += ["## State reached (static facts left out)", "", "```"]
    out += [facts_str(fluents(analysis)), "```", ""]
    return "\n".join(out)


def write_outputs(analysis: Analysis, out_dir: Path) -> list[Path]:
    """Write ``plan.txt`` (transcribed PDDL plan), ``problem.pddl`` and ``report.md``."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        plan = out_dir / "plan.txt"
        lines = [str(a) for a in analysis.actions]
        lines.append(f"; cost = {len(analysis.actions)} (unit cost)")
        lines.append(f"; transcribed from {analysis.transcript.source} by cake_drake.saycan")
        lines.append(f"; {outcome(analysis)}")
        plan.write_text("\n".join(lines) + "\n", encoding="utf-8")
        problem = out_dir / "problem.pddl"
        problem.write_text(analysis.problem.text, encoding="utf-8")
        report = out_dir / "report.md"
        report.write_text(render_markdown(analysis), encoding="utf-8")
    except OSError as e:
        raise InputError(f"{out_dir}: cannot write the outputs: {e.strerror or e}") from None
    return [plan, problem, report]
