"""The project's own file formats, in one home read by every layer: the trajectory a run
follows (``trajectory.npz``: :func:`save_npz`, :func:`load_npz`) and the phases it names,
and the one checked reader of ``.npz`` files (trajectories and run logs).

:func:`read_npz` refuses, before decompressing anything, a file over the input limit or
whose arrays (all of them, by their npy headers) would decompress past
:data:`MAX_NPZ_ARRAY_BYTES`; then it reads the arrays the caller names, and only those,
and checks each one's shape against the caller's expectation. Every failure is one
:class:`InputError` line naming the file, the array and what would be valid; nothing
is unpickled. The kinds' own checks (times that increase, seven joints) stay with their
readers: :func:`load_npz` here, :func:`cake_drake.learning.residual.load_logs`.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError

PHASE_NAMES = ("idle", "pre-grasp", "grasp", "lift", "transport", "place", "retract")


def read_json_mapping(path: str | Path, what: str) -> dict:
    """A JSON file that holds a mapping (``what`` says whose, for the message): one line
    naming the file otherwise."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"{path}: unreadable ({e})") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: holds a {type(data).__name__}, not a mapping ({what})")
    return data


#: The most an .npz's arrays may hold once decompressed (a run's trajectory is ~1 MB).
MAX_NPZ_ARRAY_BYTES = 256 * 2**20

#: A shape expectation: each entry an int (that size), "N" (the same length for every
#: array that says N) or None (any size).
Shape = tuple[int | str | None, ...]


def npz_headers(path: Path, expected: str) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Every array's (shape, dtype) by its npy header, nothing decompressed past it."""
    from cake_drake.symbolic.sexpr import MAX_INPUT_BYTES

    if path.exists() and not path.is_file():
        raise InputError(f"{path}: not a regular file; {expected}")
    if not path.is_file():
        raise InputError(f"{path}: no such file ({expected})")
    if path.stat().st_size > MAX_INPUT_BYTES:
        raise InputError(
            f"{path}: {path.stat().st_size / 1e6:.0f} MB is too large "
            f"(at most {MAX_INPUT_BYTES // 2**20} MiB); {expected}"
        )
    if not zipfile.is_zipfile(path):
        raise InputError(
            f"{path}: not a readable .npz (not a zip archive: truncated, or another kind of "
            f"file); {expected}"
        )
    out, total = {}, 0
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with archive.open(info) as f:
                    major, _ = np.lib.format.read_magic(f)
                    read = (
                        np.lib.format.read_array_header_1_0
                        if major == 1
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, dtype = read(f)
                total += int(np.prod(shape, dtype=object)) * dtype.itemsize
                if total > MAX_NPZ_ARRAY_BYTES:
                    raise InputError(
                        f"{path}: its arrays hold more than {MAX_NPZ_ARRAY_BYTES // 2**20} MiB "
                        f"({info.filename[:-4]!r} has shape {shape}); {expected}"
                    )
                out[info.filename[:-4]] = (tuple(shape), dtype)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise InputError(f"{path}: unreadable ({e}); {expected}") from None
    return out


def read_npz(path: str | Path, expected: str, shapes: Mapping[str, Shape]) -> dict[str, np.ndarray]:
    """The arrays of ``shapes`` from the .npz at ``path``, checked (see the module).

    ``expected`` says what the file should be (the end of every message); an array of
    ``shapes`` that is missing, not numbers, of another shape, or unreadable (a truncated
    file) is one line naming it. Other arrays are only looked at by their headers.
    """
    path = Path(path)
    headers = npz_headers(path, expected)
    for name, want in shapes.items():
        if name not in headers:
            raise InputError(f"{path}: missing array {name!r}; {expected} holds "
                             f"{', '.join(shapes)}")  # fmt: skip
        shape, dtype = headers[name]
        if dtype.kind not in "biuf":
            raise InputError(f"{path}: array {name!r} must hold numbers, not {dtype}")
        if len(shape) != len(want) or any(
            isinstance(w, int) and s != w for s, w in zip(shape, want, strict=False)
        ):
            shown = "(" + ", ".join("any" if w is None else str(w) for w in want) + ")"
            raise InputError(f"{path}: array {name!r} has shape {shape}; expected {shown}")
    lengths = {headers[n][0][0] for n, w in shapes.items() if w and w[0] == "N"}
    if len(lengths) > 1:
        said = ", ".join(f"{n} {headers[n][0][0]}" for n, w in shapes.items() if w and w[0] == "N")
        raise InputError(f"{path}: its arrays disagree on the number of samples ({said})")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: np.asarray(data[name]) for name in shapes}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise InputError(f"{path}: unreadable ({e}); {expected}") from None


def save_npz(path: str | Path, samples: dict[str, np.ndarray], actions: list[str]) -> None:
    """Write samples plus the phase and action names (whole, or not at all)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part.npz")
    np.savez_compressed(
        tmp, **samples, phases=np.array(PHASE_NAMES), actions=np.array(actions, dtype=str)
    )
    tmp.replace(path)


REQUIRED = ("t", "q", "gripper")


def load_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Read a ``trajectory.npz``; bad files give one clear line."""
    path = Path(path)
    expected = "expected a trajectory.npz written by python -m cake_drake.run"
    npz_headers(path, expected)  # refused unread: not a file, too large, not an archive
    try:
        with np.load(path, allow_pickle=False) as data:
            if not hasattr(data, "files"):  # a bare .npy array, not an archive
                raise InputError(f"{path}: a single .npy array, not an .npz archive; {expected}")
            out = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise InputError(f"{path}: no such file ({expected})") from None
    except InputError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, TypeError) as e:
        raise InputError(f"{path}: not a readable .npz trajectory ({e}); {expected}") from None
    numeric = [k for k in ("t", "q", "gripper") if k in out and out[k].dtype.kind not in "iuf"]
    if numeric:
        raise InputError(
            f"{path}: array {numeric[0]!r} must hold numbers, not {out[numeric[0]].dtype}"
        )
    missing = [k for k in REQUIRED if k not in out]
    if missing:
        raise InputError(
            f"{path}: missing array {missing[0]!r}; a trajectory needs {', '.join(REQUIRED)}"
        )
    t, q = out["t"], out["q"]
    if q.ndim != 2 or q.shape[1] != 7 or len(t) != len(q) or len(t) < 4:
        raise InputError(
            f"{path}: q has shape {q.shape} for {len(t)} times; expected (N, 7) with N >= 4"
        )
    if not np.all(np.diff(t) > 0):
        raise InputError(f"{path}: times in 't' must strictly increase")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(t))):
        raise InputError(f"{path}: 't' and 'q' must be finite numbers")
    return out
