"""The :class:`Plan` value and plan files.

``plan.txt`` holds one ``(action args)`` per line, then ``; cost = N (unit cost)``
(as Fast Downward's ``sas_plan``) and ``;`` comment lines naming the planner,
search, heuristic, whether the plan is optimal, the time, and (for a portfolio
such as ``auto``) which planner was asked for and why this one answered. The reader also
accepts pyperplan's ``.soln`` (actions only) and ``sas_plan``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cake_drake.errors import InputError, OutputError
from cake_drake.symbolic.pddl import GroundAction
from cake_drake.symbolic.sexpr import read_text


@dataclass(frozen=True)
class Plan:
    """A sequence of ground actions plus how it was found.

    ``time_s`` is the planner's wall-clock time (grounding and search for
    pyperplan; the whole subprocess for Fast Downward). ``optimal`` is True
    when the planner guarantees no shorter plan exists. ``planner`` is the
    planner that produced the plan; ``requested`` the one asked for (``auto``
    for the portfolio; empty or equal to ``planner`` otherwise) and
    ``selection`` why the portfolio's answer came from ``planner``.
    """

    actions: tuple[GroundAction, ...]
    planner: str
    search: str
    heuristic: str
    time_s: float
    optimal: bool = False
    requested: str = ""
    selection: str = ""

    @property
    def portfolio(self) -> bool:
        """True when a portfolio (``auto``) chose the planner that produced this plan."""
        return bool(self.requested) and self.requested != self.planner

    @property
    def length(self) -> int:
        return len(self.actions)

    def note(self) -> str:
        """One line: ``planner X: search Y, heuristic Z, N actions (optimal), T ms``,
        then ``; chosen by auto: <why>`` when a portfolio chose X."""
        kind = "optimal" if self.optimal else "satisficing"
        note = (
            f"planner {self.planner}: search {self.search}, heuristic {self.heuristic}, "
            f"{self.length} actions ({kind}), {self.time_s * 1000:.0f} ms"
        )
        if self.portfolio:
            note += f"; chosen by {self.requested}: {self.selection}"
        return note


def format_plan(plan: Plan) -> str:
    """The text of a ``plan.txt`` file for ``plan``."""
    lines = [str(a) for a in plan.actions]
    lines.append(f"; cost = {plan.length} (unit cost)")
    if plan.optimal:
        lines.append(f"; planner: {plan.planner} (optimal: no shorter plan exists)")
    else:
        lines.append(f"; planner: {plan.planner} (satisficing: a shorter plan may exist)")
    lines.append(f"; search: {plan.search}")
    lines.append(f"; heuristic: {plan.heuristic}")
    lines.append(f"; time: {plan.time_s * 1000:.1f} ms")
    if plan.portfolio:
        lines.append(f"; chosen by: {plan.requested} ({plan.selection})")
    return "\n".join(lines) + "\n"


def write_plan(plan: Plan, path: str | Path) -> None:
    """Write ``plan`` to ``path`` in the ``plan.txt`` format."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.part")
    try:  # whole or not at all: a full disk leaves the old file (or none), never half
        tmp.write_text(format_plan(plan), encoding="utf-8")
        tmp.replace(path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"{path}: cannot write the plan: {e.strerror or e}") from None


# "(name arg ...)", optionally preceded by a step number "3:" and followed by a
# duration "[1]" (the format of temporal planners and VAL).
_STEP = re.compile(
    r"^(?:\d+(?:\.\d+)?\s*:\s*)?\(\s*([^()\s]+)((?:\s+[^()\s]+)*)\s*\)(?:\s*\[[\d.]+\])?$"
)


def parse_plan_text(text: str, source: str = "<string>") -> tuple[GroundAction, ...]:
    """Parse plan text; ``;`` starts a comment. Raises :class:`InputError` with ``file:line``."""
    actions = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(";", 1)[0].strip()
        if not line:
            continue
        m = _STEP.match(line)
        if m is None:
            shown = line if len(line) <= 50 else line[:47] + "..."
            raise InputError(
                f"{source}:{lineno}: expected one action per line such as (unstack a b), "
                f"got '{shown}'"
            )
        actions.append(GroundAction(m.group(1).lower(), tuple(m.group(2).lower().split())))
    return tuple(actions)


def read_plan(path: str | Path) -> tuple[GroundAction, ...]:
    """Read a plan file (``plan.txt``, pyperplan ``.soln`` or Fast Downward ``sas_plan``)."""
    return parse_plan_text(read_text(path, "plan file"), str(path))


def plan_text(actions: Iterable[GroundAction]) -> str:
    """Actions one per line (pyperplan's ``.soln`` format)."""
    return "".join(f"{a}\n" for a in actions)
