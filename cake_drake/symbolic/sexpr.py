"""Reading text files and S-expressions with line and column numbers.

pyperplan's parser reports no positions, so PDDL and plan files are read here:
every atom and list remembers where it started, and every error names
``file:line:col``. Atoms are lower-cased (PDDL is case-insensitive).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from cake_drake.errors import InputError, PddlError
from cake_drake.formats import bounded_bytes
from cake_drake.paths import check_holdable


@dataclass(frozen=True)
class Atom:
    """A symbol such as ``on``, ``?x`` or ``:action``, lower-cased, with its position."""

    text: str
    line: int
    col: int


@dataclass(frozen=True)
class SList:
    """A parenthesised list; ``line``/``col`` locate its ``(``."""

    items: tuple[Atom | SList, ...]
    line: int
    col: int


Node = Atom | SList

#: Heads of the top-level sections of a PDDL file: ``(define (...) (:init ...) ...)``.
#: Finding one nested deeper means a ``)`` is missing before it.
SECTION_KEYWORDS = frozenset(
    (":requirements", ":types", ":constants", ":predicates", ":functions", ":action")
    + (":durative-action", ":derived", ":domain", ":objects", ":init", ":goal", ":metric")
)


def where(source: str, node: Node | None = None) -> str:
    """``source:line:col`` for ``node``, or just ``source``."""
    if node is None:
        return source
    return f"{source}:{node.line}:{node.col}"


#: Inputs larger than this are refused unread: no domain, problem, plan or transcript is.
#: Deepest nesting of parentheses accepted (a formula of a real domain nests < 10 deep).
MAX_DEPTH = 64


def read_text(path: str | Path, what: str = "file", allow_empty: bool = False) -> str:
    """Return the text of ``path``, or raise one-line :class:`InputError`.

    Missing files, directories, devices, unreadable files, files over
    :data:`cake_drake.formats.MAX_INPUT_BYTES` (refused unread; a pipe is read up to the
    bound), binary data (NUL bytes or invalid UTF-8) and, unless ``allow_empty``, files
    with nothing but whitespace are refused here. Every file the project reads comes through here.
    """
    check_holdable(str(path))
    p = Path(path).expanduser()
    if not p.exists():
        raise InputError(f"{path}: no such {what}")
    if p.is_dir():
        raise InputError(f"{path}: is a directory, expected a {what}")
    if p.is_char_device() or p.is_block_device() or p.is_socket():
        raise InputError(f"{path}: is a device or socket, not a {what}")
    data = bounded_bytes(p, lambda _, why: InputError(f"{path}: {why}; expected a {what}"))
    nul = data.find(b"\x00")
    if nul >= 0:
        raise InputError(f"{path}: not a text file (NUL byte at offset {nul}); expected a {what}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(
            f"{path}: not a UTF-8 text file (invalid byte at offset {e.start}); expected a {what}"
        ) from None
    if not text.strip() and not allow_empty:
        raise InputError(f"{path}: is empty; expected a {what}")
    return text.removeprefix("\ufeff")


def parse_sexprs(text: str, source: str = "<string>") -> list[Node]:
    """Parse ``text`` into top-level nodes; ``;`` starts a comment to end of line.

    Raises :class:`PddlError` naming the unmatched parenthesis.
    """
    stack: list[tuple[list[Node], int, int]] = []  # (items, line, col) of each open list
    top: list[Node] = []
    line, col = 1, 1
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch == "\n":
            line, col, i = line + 1, 1, i + 1
            continue
        if ch.isspace():
            i, col = i + 1, col + 1
            continue
        if ch == ";":
            while i < n and text[i] != "\n":
                i += 1
            continue
        if ch == "(":
            if len(stack) >= MAX_DEPTH:
                raise PddlError(
                    f"{source}:{line}:{col}: parentheses nested more than {MAX_DEPTH} deep; "
                    "no PDDL domain, problem or plan needs that many"
                )
            stack.append(([], line, col))
            i, col = i + 1, col + 1
            continue
        if ch == ")":
            if not stack:
                raise PddlError(f"{source}:{line}:{col}: unexpected ')' with no matching '('")
            items, l0, c0 = stack.pop()
            node = SList(tuple(items), l0, c0)
            (stack[-1][0] if stack else top).append(node)
            i, col = i + 1, col + 1
            continue
        start = i
        while i < n and not text[i].isspace() and text[i] not in "();":
            i += 1
        atom = Atom(text[start:i].lower(), line, col)
        if len(stack) > 2 and not stack[-1][0] and atom.text in SECTION_KEYWORDS:
            outer = stack[1]
            outer_head = outer[0][0].text if outer[0] and isinstance(outer[0][0], Atom) else "..."
            here = f"{source}:{stack[-1][1]}:{stack[-1][2]}"
            raise PddlError(
                f"{here}: ({atom.text} ...) is nested inside ({outer_head} ...) "
                f"opened at line {outer[1]}: a ')' is missing between line {outer[1]} "
                f"and line {line}"
            )
        col += i - start
        (stack[-1][0] if stack else top).append(atom)
    if stack:
        _, l0, c0 = stack[-1]
        raise PddlError(
            f"{source}:{l0}:{c0}: this '(' is never closed: a ')' is missing inside or after it "
            f"({len(stack)} unclosed at end of file)"
        )
    return top


def parse_file(path: str | Path, what: str = "PDDL file") -> tuple[str, list[Node]]:
    """Read ``path`` and parse it; returns the text and the top-level nodes."""
    text = read_text(path, what)
    return text, parse_sexprs(text, str(path))
