"""SayCan-style transcripts: a human request, then the robot's numbered steps.

Accepted layout (lines starting with ``#`` are comments)::

    Human: I'm hungry, could you bring me an apple?
    Robot: I would 1. find an apple, 2. pick up the apple, 3. bring it to you, 4. done.

The steps may also stand one per line (``1. find an apple``), with or without
the ``Robot:`` label. Other ``Label:`` lines (an ``Explanation:``, say) are kept
as notes and not read as steps.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from cake_drake.errors import InputError
from cake_drake.symbolic.sexpr import read_text

_LABEL = re.compile(r"^\s*([A-Za-z][A-Za-z ]{0,20}):\s*(.*)$")
_HUMAN_LABELS = {"human", "user", "person"}
_ROBOT_LABELS = {"robot", "assistant"}
# A step number: "3." followed by a space, not inside a word or a decimal number.
_STEP = re.compile(r"(?<![\w.])(\d{1,3})\.(?=\s)")


@dataclass(frozen=True)
class Step:
    """One numbered step: its number, its text (normalised) and the line it starts on."""

    number: int
    text: str
    line: int


@dataclass(frozen=True)
class Transcript:
    request: str
    steps: tuple[Step, ...]
    source: str = "<string>"
    notes: tuple[str, ...] = field(default=())


def normalise(text: str) -> str:
    """Lower case, single spaces, no trailing punctuation or 'and'."""
    text = re.sub(r"\s+", " ", text.lower()).strip()
    text = text.strip(" ,;:.!?")
    text = re.sub(r"(,| and| then)+$", "", text).strip(" ,;:.!?")
    return text


def parse_transcript(text: str, source: str = "<string>") -> Transcript:
    """Parse transcript text; :class:`InputError` when there are no numbered steps."""
    request_parts: list[str] = []
    notes: list[str] = []
    chunks: list[tuple[int, str]] = []  # (line number, text that may hold steps)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        m = _LABEL.match(line)
        if m and not _STEP.match(line):
            label, rest = m.group(1).strip().lower(), m.group(2)
            if label in _HUMAN_LABELS:
                request_parts.append(rest.strip())
            elif label in _ROBOT_LABELS:
                chunks.append((lineno, rest))
            else:
                notes.append(line)
            continue
        chunks.append((lineno, line))

    # Find every step marker across the robot text, remembering its line.
    markers: list[tuple[int, int, int, int]] = []  # (chunk index, start, end, number)
    for ci, (_, chunk) in enumerate(chunks):
        for m in _STEP.finditer(chunk):
            markers.append((ci, m.start(), m.end(), int(m.group(1))))
    if not markers:
        raise InputError(
            f"{source}: no numbered robot steps found; expected e.g. "
            "'Robot: 1. find an apple, 2. pick up the apple, 3. done.'"
        )
    steps = []
    for k, (ci, _start, end, number) in enumerate(markers):
        parts = []
        nxt = markers[k + 1] if k + 1 < len(markers) else None
        for cj in range(ci, len(chunks)):
            chunk = chunks[cj][1]
            lo = end if cj == ci else 0
            if nxt is not None and cj == nxt[0]:
                parts.append(chunk[lo : nxt[1]])
                break
            parts.append(chunk[lo:])
        steps.append(Step(number, normalise(" ".join(parts)), chunks[ci][0]))
    expected = list(range(1, len(steps) + 1))
    if [s.number for s in steps] != expected:
        notes.append(
            "steps are not numbered 1, 2, 3, ...: read in the order written "
            f"({', '.join(str(s.number) for s in steps)})"
        )
    return Transcript(" ".join(request_parts), tuple(steps), source, tuple(notes))


def load_transcript(path: str | Path) -> Transcript:
    """Read and parse a transcript file (missing, empty or binary files are refused)."""
    return parse_transcript(read_text(path, "transcript (text file)"), str(path))
