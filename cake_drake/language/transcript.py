"""SayCan-style transcripts: a human request, then the robot's numbered steps.

Accepted layout (lines starting with ``#`` are comments)::

    Human: I'm hungry, could you bring me an apple?
    Explanation: The user has asked for a fruit, I will bring an apple.
    Robot: I would 1. find an apple, 2. pick up the apple, 3. bring it to you, 4. done.
    Goal: (at-location apple user)

The steps may also stand one per line, with or without the ``Robot:`` label.
A step number is read as a person reads it: ``1.``, ``1 .``, ``1)``, ``Step 1:``,
with or without a space after it (SayCan's own ``5.done``), but not inside a
word or a decimal number. Typographic punctuation is read as plain (``I’m`` is
``I'm``). A ``Goal:`` line is not part of the quoted transcript: it is the
reader's transcription of the request into a PDDL goal, used when the problem
has none. Other ``Label:`` lines (an ``Explanation:``) are kept as notes.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path

from cake_drake.errors import InputError
from cake_drake.symbolic.sexpr import read_text

_LABEL = re.compile(r"^\s*([A-Za-z][A-Za-z ]{0,20}):\s*(.*)$")
_HUMAN_LABELS = {"human", "user", "person"}
_ROBOT_LABELS = {"robot", "assistant", "plan"}
_GOAL_LABELS = {"goal"}
_NOTE_LABELS = {"explanation", "note", "scene", "notes"}
# A step number: any number of digits, then "." / ")" / ":" (spaces allowed before it), not part of
# a word, a decimal number or a time; optionally preceded by "step".
_STEP = re.compile(
    r"(?<![^\s,;:(])"  # at the start, or after a space or a separator
    r"(?:step\s*)?"
    r"(\d+)\s*[.):](?![\d.)])",
    re.IGNORECASE,
)

#: Typographic characters and their plain equivalents.
_PLAIN = str.maketrans(
    {
        "\u2018": "'",
        "\u2019": "'",
        "\u201a": "'",
        "\u2032": "'",
        "\u00b4": "'",
        "`": "'",
        "\u201c": '"',
        "\u201d": '"',
        "\u201e": '"',
        "\u2010": "-",
        "\u2011": "-",
        "\u2012": "-",
        "\u2013": "-",
        "\u2014": "-",
        "\u2212": "-",
        "\u2026": "...",
        "\u00a0": " ",
        "\u2009": " ",
        "\u202f": " ",
        "\u200b": "",
        "\ufeff": "",
    }
)


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
    goal: str | None = None  # a PDDL goal formula from a ``Goal:`` line
    goal_line: int = 0


def plain(text: str) -> str:
    """Typographic quotes, dashes and spaces as plain ASCII (NFKC first: full-width digits)."""
    return unicodedata.normalize("NFKC", text).translate(_PLAIN)


def normalise(text: str) -> str:
    """Lower case, plain punctuation, single spaces, no trailing punctuation or 'and'."""
    text = re.sub(r"\s+", " ", plain(text).lower()).strip()
    before = None
    while text != before:  # "and!, and" -> "": trailing punctuation and conjunctions, in turn
        before = text
        text = re.sub(r"(^|\s)(and|then)$", "", text.strip(" ,;:.!?\"'(-*"))
    return text


def split_steps(chunks: list[tuple[int, str]], source: str) -> list[Step]:
    """Cut robot text (a list of (line number, text)) at its step numbers."""
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
    return steps


def parse_transcript(text: str, source: str = "<string>") -> Transcript:
    """Parse transcript text; :class:`InputError` when there are no numbered steps."""
    request_parts: list[str] = []
    notes: list[str] = []
    goal: str | None = None
    goal_line = 0
    chunks: list[tuple[int, str]] = []  # (line number, text that may hold steps)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = plain(raw).strip()
        if not line or line.startswith("#"):
            continue
        m = _LABEL.match(line)
        if m and not _STEP.match(line):
            label, rest = m.group(1).strip().lower(), m.group(2)
            if label in _HUMAN_LABELS:
                request_parts.append(rest.strip())
            elif label in _ROBOT_LABELS:
                chunks.append((lineno, rest))
            elif label in _GOAL_LABELS:
                if goal is not None:
                    raise InputError(f"{source}:{lineno}: a second Goal: line (one is allowed)")
                goal, goal_line = rest.strip(), lineno
                if not goal:
                    raise InputError(f"{source}:{lineno}: empty Goal: line; expected a PDDL goal")
            elif label not in _NOTE_LABELS and _STEP.search(rest):
                chunks.append((lineno, rest))  # "I would: 1. find ...": steps after all
            else:
                notes.append(line)
            continue
        chunks.append((lineno, line))

    steps = split_steps(chunks, source)
    if [s.number for s in steps] != list(range(1, len(steps) + 1)):
        notes.append(
            "steps are not numbered 1, 2, 3, ...: read in the order written "
            f"({', '.join(str(s.number) for s in steps)})"
        )
    return Transcript(" ".join(request_parts), tuple(steps), source, tuple(notes), goal, goal_line)


def load_transcript(path: str | Path) -> Transcript:
    """Read and parse a transcript file (missing, empty or binary files are refused)."""
    return parse_transcript(read_text(path, "transcript (text file)"), str(path))
