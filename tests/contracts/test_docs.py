"""Every command the README and docs/ show is run, with the outcome written under it.

A shell block (```sh) is followed by its outcome line:

    > exit N · prints "a phrase"

Its commands run in order, in a fresh folder holding copies of `models/`, `examples/`,
`notebooks/` and `tests/data/` (as a reader's checkout does); every command but the last
must succeed, and the last must end with exit N and print the phrase (stdout or stderr).
The only blocks not run here are setup commands (make, pip, apt-get, ray start), marked
`> not run by the doc tests: WHY`, and commands a test of their own runs and checks more
closely, marked `> not run by the doc tests: tests/FILE.py runs this command ...` (that
file must hold each command verbatim). Links to files in the repository must resolve.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.helpers import ROOT

PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
OUTCOME = re.compile(r'^> exit (\d+)(?: · prints "(.+)")?$')
NOT_RUN = "> not run by the doc tests: "
SETUP = ("make ", "pip install", "sudo ", "apt-get ", "ray start")


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # of the opening fence, 1-based
    commands: tuple[str, ...]
    outcome: str  # the line after the block

    @property
    def name(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def blocks() -> list[Block]:
    found = []
    for page in PAGES:
        lines = page.read_text().split("\n")
        i = 0
        while i < len(lines):
            if lines[i].strip() == "```sh":
                j = i + 1
                while lines[j].strip() != "```":
                    j += 1
                commands = tuple(
                    ln.strip() for ln in lines[i + 1 : j] if ln.strip() and not ln.startswith("#")
                )
                after = lines[j + 1] if j + 1 < len(lines) else ""
                found.append(Block(page, i + 1, commands, after))
                i = j
            i += 1
    return found


BLOCKS = blocks()


def test_the_pages_have_shell_blocks():
    assert len(BLOCKS) >= 15, [b.name for b in BLOCKS]


@pytest.mark.parametrize("block", BLOCKS, ids=[b.name for b in BLOCKS])
def test_every_shell_block_states_its_outcome(block):
    if block.outcome.startswith(NOT_RUN):
        why = block.outcome.removeprefix(NOT_RUN)
        test = re.match(r"(tests/[\w/]+\.py) runs this command", why)
        if test is not None:
            text = (ROOT / test.group(1)).read_text()
            missing = [c for c in block.commands if c not in text]
            assert not missing, f"{block.name}: {test.group(1)} does not hold {missing}"
            return
        assert all(c.startswith(SETUP) for c in block.commands), (
            f"{block.name}: only setup commands may go unrun: {block.commands}"
        )
    else:
        assert OUTCOME.match(block.outcome), (
            f'{block.name}: the line after the block must be > exit N · prints "..."'
        )


def test_no_page_shows_a_command_outside_a_shell_block():
    """A `$ command` transcript would escape the tests: commands go in ```sh blocks."""
    for page in PAGES:
        for n, line in enumerate(page.read_text().split("\n"), start=1):
            assert not line.startswith("$ "), f"{page.relative_to(ROOT)}:{n}: {line}"


def _workspace(tmp_path: Path) -> Path:
    for folder in ("models", "examples", "notebooks"):
        shutil.copytree(ROOT / folder, tmp_path / folder)
    shutil.copytree(ROOT / "tests" / "data", tmp_path / "tests" / "data")
    return tmp_path


RUN = [b for b in BLOCKS if OUTCOME.match(b.outcome)]


@pytest.mark.slow
@pytest.mark.parametrize("block", RUN, ids=[b.name for b in RUN])
def test_the_documented_command_does_what_the_page_says(block, tmp_path):
    cwd = _workspace(tmp_path)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code, phrase = OUTCOME.match(block.outcome).groups()
    for k, command in enumerate(block.commands):
        argv = shlex.split(command)
        assert argv[0] == "python", f"{block.name}: a documented command runs python: {command}"
        r = subprocess.run(
            [sys.executable, *argv[1:]], cwd=cwd, env=env, capture_output=True, text=True,
            timeout=900,
        )  # fmt: skip
        said = r.stdout + r.stderr
        if k < len(block.commands) - 1:
            assert r.returncode == 0, f"{block.name}: {command}\n{said[-2000:]}"
            continue
        assert r.returncode == int(code), f"{block.name}: {command} exit {r.returncode}\n{said}"
        assert "Traceback" not in said, said
        if phrase:
            assert phrase in said, f"{block.name}: {command} did not print {phrase!r}\n{said}"


LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


@pytest.mark.parametrize("page", PAGES, ids=[p.name for p in PAGES])
def test_every_link_to_a_file_resolves(page):
    for target in LINK.findall(page.read_text()):
        if "://" in target or target.startswith("mailto:"):
            continue
        assert (page.parent / target).exists(), f"{page.relative_to(ROOT)}: no {target}"
