"""Outputs are one transaction: staged in a hidden sibling folder, then swapped in whole.

A run's files are written to ``.<name>.staging-<pid>/`` beside the output folder. On
:meth:`OutputDir.commit` the old folder is moved aside and the staged one renamed into
its place, so the folder holds exactly one run's files - never two runs mixed, never a
file an earlier run wrote that this one did not, never a half-written file. On any
failure, Ctrl-C or SIGTERM the staging folder is removed and the old folder is left as
it was; a staging folder left by a killed process is removed by the next run.

Only a folder that is new, empty, or an earlier run's output folder (it holds the
:data:`MARKER` file) is ever replaced: anything else is refused before the run starts.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

from cake_drake.errors import InputError, OutputError

#: Written into every output folder; only such a folder is replaced by a new run.
MARKER = ".cake_drake-outputs"
#: The files a run writes (folders from before the marker existed, holding only these, are
#: taken as earlier output folders too).
KNOWN = {
    "plan.txt", "trajectory.npz", "final_state.png", "joint4_torque.png", "summary.json",
    "scenario.yaml", "replay.html", "kd_comparison.png", "gains.json", "problem.pddl",
    "report.md", "reference.npz", MARKER,
}  # fmt: skip
_LEFTOVER = re.compile(r"^\.(?P<name>.+)\.(staging|old)-(?P<pid>\d+)$")


def check_output_folder(out: str | Path, whole: bool = True) -> None:
    """Refuse, before any work, an output folder this run could not or must not replace.

    ``whole=False`` for a folder that is added to rather than replaced (a sweep's): then
    only that it is a folder, or can become one, and that it is writable.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder; choose another output folder")
    if out.is_dir() and whole:
        entries = {p.name for p in out.iterdir()}
        if entries and MARKER not in entries and not entries <= KNOWN:
            strange = sorted(entries - KNOWN)
            raise InputError(
                f"{out}: holds files that are not a run's outputs ({', '.join(strange[:3])}"
                f"{', ...' if len(strange) > 3 else ''}); a run replaces its output folder "
                "whole, so choose a new or empty folder"
            )
    parent = _parent(out)
    existing = next((p for p in (parent, *parent.parents) if p.exists()), Path("/"))
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{out}: cannot write there ({existing} is not writable)")


def _parent(out: Path) -> Path:
    return out.resolve().parent


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_leftovers(out: Path) -> None:
    """Remove staging or old folders of ``out`` left by processes that no longer run."""
    parent = _parent(out)
    if not parent.is_dir():
        return
    for p in parent.iterdir():
        m = _LEFTOVER.match(p.name)
        if m and m["name"] == out.name and not _alive(int(m["pid"])):
            shutil.rmtree(p, ignore_errors=True)


class OutputDir:
    """Stage files for ``out``; :meth:`commit` swaps them in, :meth:`discard` drops them.

    Use as a context manager: an exception (or Ctrl-C, or SIGTERM turned into
    ``SystemExit`` by the command-line tools) inside the block discards the staging.
    """

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        check_output_folder(self.out)
        parent = _parent(self.out)
        try:
            parent.mkdir(parents=True, exist_ok=True)
            remove_leftovers(self.out)
            self.staging = parent / f".{self.out.name}.staging-{os.getpid()}"
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging.mkdir()
        except OSError as e:
            raise OutputError(f"{out}: cannot create the output folder ({e.strerror})") from None
        self.names: list[str] = []

    def __enter__(self) -> OutputDir:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is not None:
            self.discard()

    def path(self, name: str) -> Path:
        self.names.append(name)
        return self.staging / name

    def write_text(self, name: str, text: str) -> None:
        try:
            self.path(name).write_text(text, encoding="utf-8")
        except OSError as e:
            raise OutputError(f"{self.out / name}: cannot write ({e.strerror or e})") from None

    def write_json(self, name: str, data: object) -> None:
        self.write_text(name, json.dumps(data, indent=2, sort_keys=False) + "\n")

    def commit(self) -> list[Path]:
        """Swap the staged folder in for ``out`` (the old one is moved aside, then removed)."""
        try:
            (self.staging / MARKER).write_text("written by cake_drake; replaced whole by a run\n")
            old = _parent(self.out) / f".{self.out.name}.old-{os.getpid()}"
            if self.out.exists():
                os.rename(self.out, old)
            os.rename(self.staging, self.out)
        except OSError as e:
            self.discard()
            raise OutputError(
                f"{self.out}: cannot put the outputs in place ({e.strerror})"
            ) from None
        shutil.rmtree(old, ignore_errors=True)
        return [self.out / n for n in self.names if (self.out / n).exists()]

    def discard(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)
