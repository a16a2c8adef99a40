"""Outputs are one transaction, and a command replaces only what it wrote itself.

A command's files are staged in a hidden folder inside the output folder
(``.staging-<pid>/``). On :meth:`OutputDir.commit` the entries this command wrote last
time are moved aside and the staged ones renamed into place, each a rename on the same
file system; then the folder's marker (:data:`MARKER`) records what was written, by which
command. A failure while staging, Ctrl-C or SIGTERM removes the staging folder and
leaves the output folder as it was; a failure while committing puts every moved entry
back. A staging or moved-aside folder left by a killed process is removed by the next
command that writes there.

Ownership is by proof, not by file name: only the entries the marker lists for the same
command are replaced or removed. Everything else in the folder - the user's own files,
another command's outputs (``outputs/saycan/...`` inside ``outputs/``) - is kept. A name
the command is about to write that is held by something it did not write is refused
before any work, with one line. So is an input of the run that lies among the entries
the run would replace, a special file, a folder under a regular file, and a link to
nowhere; ``~`` is expanded and links are followed (never moved).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Iterable
from pathlib import Path

from cake_drake.errors import InputError, OutputError

#: Written into every output folder: JSON ``{"written": {command: [entry, ...]}}``.
MARKER = ".cake_drake-outputs"
#: What a run wrote before the marker listed its entries (an empty or plain-text marker):
#: in such a folder these names, and only these, are taken as written by cake_drake.
LEGACY = {
    "plan.txt", "trajectory.npz", "final_state.png", "joint4_torque.png", "summary.json",
    "scenario.yaml", "replay.html", "kd_comparison.png", "gains.json", "problem.pddl",
    "report.md", "reference.npz",
}  # fmt: skip
_LEFTOVER = re.compile(r"^\.(staging|old)-(?P<pid>\d+)$")


def output_path(path: str | Path) -> Path:
    """``path`` with ``~`` expanded and links followed (a link is written through, never
    replaced); refused when it is a link to nowhere."""
    path = Path(path).expanduser()
    if path.is_symlink() and not path.exists():
        raise InputError(f"{path}: a link to nowhere ({os.readlink(path)}); choose another path")
    return path.resolve()


def _no_file_above(path: Path, shown: Path) -> None:
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(
                    f"{shown}: {parent} is a file, not a folder; choose another output path"
                )
            if not os.access(parent, os.W_OK | os.X_OK):
                raise InputError(f"{shown}: cannot write there ({parent} is not writable)")
            return


def check_output_file(path: str | Path) -> Path:
    """The path a single output file (a plan, a picture) may be written to, before any work:
    a new file or a regular one, in a folder that is (or can become) a folder."""
    shown = Path(path)
    real = output_path(path)
    if real.exists() and not real.is_file():
        kind = "a folder" if real.is_dir() else "a special file (device, pipe or socket)"
        raise InputError(f"{shown}: is {kind}, not a regular file; give a file path")
    _no_file_above(real, shown)
    return real


def written(folder: Path) -> dict[str, set[str]]:
    """What the folder's marker says each command wrote there (empty without a marker)."""
    marker = folder / MARKER
    try:
        text = marker.read_text(encoding="utf-8")
    except (FileNotFoundError, NotADirectoryError):
        return {}
    except (OSError, UnicodeDecodeError):
        text = ""
    try:
        data = json.loads(text)
        listed = data["written"]
        return {str(c): {str(e) for e in entries} for c, entries in listed.items()}
    except (ValueError, KeyError, TypeError, AttributeError):
        # A marker from before the manifest: the run's known names count as written.
        present = {p.name for p in folder.iterdir()} & LEGACY
        return {"*": present}


def _owned(listed: dict[str, set[str]], command: str) -> set[str]:
    return listed.get(command, set()) | listed.get("*", set())


def check_output_folder(
    out: str | Path,
    command: str = "run",
    names: Iterable[str] = (),
    inputs: Iterable[str | Path] = (),
) -> Path:
    """Refuse, before any work, an output folder ``command`` could not or must not write.

    ``names`` are the entries the command may write; each must be free or written by the
    same command before. ``inputs`` are the files the command reads: none may be among
    the entries it would replace. Returns the folder as written to (links followed).
    """
    shown = Path(out)
    real = output_path(out)
    if real.exists() and not real.is_dir():
        raise InputError(f"{shown}: exists and is not a folder; choose another output folder")
    _no_file_above(real, shown)
    if not real.is_dir():
        return real
    if not os.access(real, os.W_OK | os.X_OK):
        raise InputError(f"{shown}: cannot write there (the folder is not writable)")
    listed = written(real)
    ours = _owned(listed, command)
    others = {e: c for c, entries in listed.items() if c not in (command, "*") for e in entries}
    for name in sorted(set(names) - ours):
        if not os.path.lexists(real / name):
            continue
        by = f"the {others[name]} command" if name in others else "you (not cake_drake)"
        raise InputError(
            f"{shown / name}: written by {by}; {command} writes {name} there and replaces only "
            "what it wrote itself: move it away or choose another output folder"
        )
    for given in inputs:
        try:
            path = Path(given).expanduser().resolve()
            relative = path.relative_to(real)
        except (ValueError, OSError):
            continue
        if relative.parts and relative.parts[0] in ours:
            raise InputError(
                f"{given}: an input of this {command} lies in its output folder {shown}, among "
                "the outputs it replaces; copy it elsewhere or choose another output folder"
            )
    return real


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_leftovers(folder: Path) -> None:
    """Remove staging or moved-aside folders left in ``folder`` by processes now gone."""
    if not folder.is_dir():
        return
    for p in folder.iterdir():
        m = _LEFTOVER.match(p.name)
        if m and int(m["pid"]) != os.getpid() and not _alive(int(m["pid"])):
            shutil.rmtree(p, ignore_errors=True)


def _write_marker(folder: Path, listed: dict[str, set[str]], scratch: Path) -> None:
    data = {"written": {c: sorted(e) for c, e in sorted(listed.items()) if e and c != "*"}}
    tmp = scratch / MARKER
    tmp.write_text(
        "{\n"
        '  "note": "written by cake_drake: each command replaces only its own entries",\n'
        f'  "written": {json.dumps(data["written"], sort_keys=True)}\n'
        "}\n",
        encoding="utf-8",
    )
    os.replace(tmp, folder / MARKER)


def claim_folder(out: str | Path, command: str, names: Iterable[str]) -> Path:
    """Make ``out`` (checked first) and record ``names`` as ``command``'s entries, for a
    command that writes into its folder bit by bit (a sweep) rather than in one commit."""
    real = check_output_folder(out, command, names)
    try:
        real.mkdir(parents=True, exist_ok=True)
        listed = written(real)
        listed[command] = _owned(listed, command) | set(names)
        listed.pop("*", None)
        _write_marker(real, listed, real)
    except OSError as e:
        raise OutputError(f"{out}: cannot create the output folder ({e.strerror or e})") from None
    return real


class OutputDir:
    """Stage files for ``out``; :meth:`commit` puts them in place, :meth:`discard` drops them.

    Use as a context manager: an exception (or Ctrl-C, or SIGTERM) inside the block
    discards the staging. ``command`` names whose outputs these are; ``names`` every
    entry it may write, ``inputs`` the files it reads (both checked up front).
    """

    def __init__(
        self,
        out: str | Path,
        command: str = "run",
        names: Iterable[str] = (),
        inputs: Iterable[str | Path] = (),
    ) -> None:
        self.out = Path(out)
        self.command = command
        self.declared = set(names)
        self.real = check_output_folder(out, command, self.declared, inputs)
        self.created: list[Path] = [p for p in (self.real, *self.real.parents) if not p.exists()]
        try:
            self.real.mkdir(parents=True, exist_ok=True)
            remove_leftovers(self.real)
            self.staging = self.real / f".staging-{os.getpid()}"
            shutil.rmtree(self.staging, ignore_errors=True)
            self.staging.mkdir()
        except OSError as e:
            self._remove_created()
            raise OutputError(f"{out}: cannot create the output folder ({e.strerror})") from None
        self.names: list[str] = []

    def __enter__(self) -> OutputDir:
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is not None:
            self.discard()

    def path(self, name: str) -> Path:
        if self.declared and name not in self.declared:
            raise OutputError(f"{self.out}: {name} is not among the outputs checked up front")
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
        """Put the staged entries in place of this command's earlier ones (the rest stays)."""
        real = self.real
        listed = written(real)
        # Checked again: something may have appeared while the command worked.
        check_output_folder(real, self.command, set(os.listdir(self.staging)))
        old = _owned(listed, self.command)
        aside = real / f".old-{os.getpid()}"
        moved: list[str] = []
        placed: list[str] = []
        try:
            aside.mkdir(exist_ok=True)
            for name in sorted(old):
                if os.path.lexists(real / name):
                    os.rename(real / name, aside / name)
                    moved.append(name)
            new = sorted(os.listdir(self.staging))
            for name in new:
                os.rename(self.staging / name, real / name)
                placed.append(name)
            listed.pop("*", None)
            listed[self.command] = set(new)
            _write_marker(real, listed, aside)
        except OSError as e:
            for name in placed:
                os.rename(real / name, self.staging / name)
            for name in moved:
                os.rename(aside / name, real / name)
            shutil.rmtree(aside, ignore_errors=True)
            self.discard()
            raise OutputError(
                f"{self.out}: cannot put the outputs in place ({e.strerror})"
            ) from None
        shutil.rmtree(aside, ignore_errors=True)
        shutil.rmtree(self.staging, ignore_errors=True)
        return [self.out / n for n in self.names if (real / n).exists()]

    def discard(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)
        self._remove_created()

    def _remove_created(self) -> None:
        for folder in self.created:  # innermost first; only if still empty
            try:
                folder.rmdir()
            except OSError:
                break
