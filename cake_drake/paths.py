"""Where the project's files are: ``package://cake_drake/...`` and the ``models/`` folder.

Every path a user gives (a scenario's fields, a flag, a checkpoint's base) is either a
file system path or ``package://cake_drake/...``, which names a file under the
repository's ``models/`` folder, as Drake's ``PackageMap`` does for the scene
(``models/package.xml``). :func:`resolve_path` turns one into a file system path;
:func:`portable_path` writes one back, as a package URL where it is a shipped file, so a
saved scenario runs again from any working folder and on any machine. Below every layer:
imports nothing of the project's but its errors.
"""

from __future__ import annotations

import os
import posixpath
from pathlib import Path

from cake_drake.errors import InputError, shown_path

#: The repository folder that holds the scene, the robot, the PDDL files and the shipped
#: learned layers.
MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
#: The package URL of ``models/``.
PACKAGE = "package://cake_drake/"


#: What Linux's file systems hold: a name of 255 bytes, a path of 4,095.
NAME_MAX = 255
PATH_MAX = 4095


def check_holdable(path: str) -> None:
    """Refuse, as bad input, a path no file system can hold: the OS's own error for it
    reads as an output that could not be written, or as a traceback."""
    if "\x00" in path:
        raise InputError(f"{path!r}: a path cannot hold a NUL byte")
    raw = os.fsencode(path)
    if len(raw) > PATH_MAX or any(len(name) > NAME_MAX for name in raw.split(b"/")):
        raise InputError(
            f"{shown_path(path)}: a path of {len(raw):,} bytes is longer than a file system holds "
            f"({PATH_MAX:,} bytes, {NAME_MAX} a name)"
        )


def resolve_path(path: str, base: Path | None = None) -> Path:
    """A path as a file system path: ``package://cake_drake/`` is ``models/``; a relative
    path is taken from ``base`` (a scenario file's folder) where one is given. A path no
    file system can hold (a NUL byte, a name or a whole too long) is refused here."""
    check_holdable(path)
    if path.startswith(PACKAGE):
        inside = posixpath.normpath(path[len(PACKAGE) :] or ".")
        if inside == ".." or inside.startswith(("../", "/")) or "\x00" in inside:
            raise InputError(
                f"{path!r}: a package URL names a file under models/ "
                "(package://cake_drake/FILE, no '..' out of it); refused unread"
            )
        return MODELS_DIR / inside
    if path.startswith("package://"):
        raise InputError(f"{path}: only package://cake_drake/... is known (the models/ folder)")
    p = Path(path).expanduser()
    return p if p.is_absolute() or base is None else base / p


def portable_path(path: str | Path) -> str:
    """``package://cake_drake/...`` for a shipped file, else the absolute path."""
    if str(path).startswith(PACKAGE):  # already portable (never a folder named package:)
        return str(path)
    given = Path(path).expanduser()
    if given.exists() and not given.is_file() and not given.is_dir():
        # A pipe (bash's <(...) is /dev/fd/N): resolving it names the pipe's inode.
        return str(given.absolute())
    p = given.resolve()
    try:
        return PACKAGE + p.relative_to(MODELS_DIR.resolve()).as_posix()
    except ValueError:
        return str(p)


__all__ = ["MODELS_DIR", "PACKAGE", "portable_path", "resolve_path"]
