"""The project's own file formats, in one home read by every layer: the trajectory a run
follows (``trajectory.npz``: :func:`save_npz`, :func:`load_npz`) and the phases it names,
and the one checked reader of ``.npz`` files (trajectories and run logs).

:func:`read_npz` refuses, before decompressing anything, a file over the input limit or
whose arrays (all of them, by their npy headers) would decompress past
:data:`MAX_NPZ_ARRAY_BYTES`; then it reads the arrays the caller names, and only those,
and checks each one's shape against the caller's expectation. Every failure is one
:class:`InputError` line naming the file, the array and what would be valid; nothing
is unpickled. The kinds' own checks (times that increase, seven joints) stay with their
readers: :func:`load_npz` here, :func:`cake_drake.learning.training.residual.load_logs`.

:func:`bounded_bytes` is the one bounded read of a whole file, and :class:`WeightsFolder`
the one reader of the NumPy checkpoints (the learned planner, the learned eyes).
"""

from __future__ import annotations

import hashlib
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


def check_format(meta: dict, path: str | Path, formats: tuple[int, ...]) -> int:
    """A description's ``format``: one of ``formats``, a whole number (``true`` is not 1,
    nor ``1.0``); one line naming the file otherwise."""
    given = meta.get("format")
    if type(given) is not int or given not in formats:
        raise InputError(
            f"{path}: field 'format' is {given!r:.40}; this version reads "
            f"{' or '.join(map(str, formats))}"
        )
    return given


#: The largest input file read at all (PDDL, plans, scenarios, checkpoints' descriptions):
#: anything larger is refused unread.
MAX_INPUT_BYTES = 16 * 1024 * 1024
#: The most an .npz's arrays may hold once decompressed (a run's trajectory is ~1 MB).
MAX_NPZ_ARRAY_BYTES = 256 * 2**20

#: A shape expectation: each entry an int (that size), "N" (the same length for every
#: array that says N) or None (any size).
Shape = tuple[int | str | None, ...]


def npz_headers(
    path: Path, expected: str, file_limit: int | None = None
) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Every array's (shape, dtype) by its npy header, nothing decompressed past it.

    Every member of the archive counts: one that is not an array (``np.savez`` writes
    only ``NAME.npy`` members), a header with a negative dimension, or arrays that add up
    past :data:`MAX_NPZ_ARRAY_BYTES` are refused before anything is decompressed. The
    file itself may be at most ``file_limit`` bytes (default: the inputs' limit,
    ``MAX_INPUT_BYTES``; an uncompressed kept episode with its frames may be larger).
    """
    limit = MAX_INPUT_BYTES if file_limit is None else file_limit
    if path.exists() and not path.is_file():
        raise InputError(f"{path}: not a regular file; {expected}")
    if not path.is_file():
        raise InputError(f"{path}: no such file ({expected})")
    if path.stat().st_size > limit:
        raise InputError(
            f"{path}: {path.stat().st_size / 1e6:.0f} MB is too large "
            f"(at most {limit // 2**20} MiB); {expected}"
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
                if info.is_dir():
                    continue
                if not info.filename.endswith(".npy"):
                    raise InputError(
                        f"{path}: member {info.filename!r} is not an array (an .npz holds "
                        f"NAME.npy members only); {expected}"
                    )
                name = info.filename[:-4]
                with archive.open(info) as f:
                    major, _ = np.lib.format.read_magic(f)
                    read = (
                        np.lib.format.read_array_header_1_0
                        if major == 1
                        else np.lib.format.read_array_header_2_0
                    )
                    shape, _, dtype = read(f)
                if any(int(d) < 0 for d in shape):
                    raise InputError(
                        f"{path}: array {name!r} claims shape {tuple(shape)}, with a negative "
                        f"dimension; {expected}"
                    )
                total += int(np.prod(shape, dtype=object)) * max(dtype.itemsize, 1)
                if total > MAX_NPZ_ARRAY_BYTES:
                    raise InputError(
                        f"{path}: its arrays hold more than {MAX_NPZ_ARRAY_BYTES // 2**20} MiB "
                        f"({name!r} has shape {tuple(shape)}); {expected}"
                    )
                out[name] = (tuple(int(d) for d in shape), dtype)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise InputError(f"{path}: unreadable ({e}); {expected}") from None
    return out


#: The dtype kinds an array may have: numbers (the default), or text.
NUMBERS, TEXT = "biuf", "U"


def read_npz(
    path: str | Path,
    expected: str,
    shapes: Mapping[str, Shape],
    optional: Mapping[str, Shape] | None = None,
    kinds: Mapping[str, str] | None = None,
    file_limit: int | None = None,
) -> dict[str, np.ndarray]:
    """The arrays of ``shapes`` (and of ``optional``, where present) from the .npz at
    ``path``, checked (see the module).

    ``expected`` says what the file should be (the end of every message); an array of
    ``shapes`` that is missing, of another kind (``kinds``: NAME -> dtype kinds, numbers
    by default), of another shape, or unreadable (a truncated file) is one line naming
    it. Other arrays are only looked at by their headers, never decompressed.
    """
    path = Path(path)
    headers = npz_headers(path, expected, file_limit)
    kinds = dict(kinds or {})
    wanted = {**{n: w for n, w in (optional or {}).items() if n in headers}, **shapes}
    for name, want in wanted.items():
        if name not in headers:
            raise InputError(f"{path}: missing array {name!r}; {expected} holds "
                             f"{', '.join(shapes)}")  # fmt: skip
        shape, dtype = headers[name]
        allowed = kinds.get(name, NUMBERS)
        if dtype.kind not in allowed or dtype.fields is not None:
            said = "text" if allowed == TEXT else "numbers"
            raise InputError(f"{path}: array {name!r} must hold {said}, not {dtype}")
        if len(shape) != len(want) or any(
            isinstance(w, int) and s != w for s, w in zip(shape, want, strict=False)
        ):
            dims = ["any" if w is None else str(w) for w in want]
            shown = f"({dims[0]},)" if len(dims) == 1 else "(" + ", ".join(dims) + ")"
            raise InputError(f"{path}: array {name!r} has shape {shape}; expected {shown}")
    lengths = {headers[n][0][0] for n, w in wanted.items() if w and w[0] == "N"}
    if len(lengths) > 1:
        said = ", ".join(f"{n} {headers[n][0][0]}" for n, w in wanted.items() if w and w[0] == "N")
        raise InputError(f"{path}: its arrays disagree on the number of samples ({said})")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {name: np.asarray(data[name]) for name in wanted}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise InputError(f"{path}: unreadable ({e}); {expected}") from None


def bounded_bytes(path: Path, bad) -> bytes:
    """A file's bytes; one over :data:`MAX_INPUT_BYTES` is refused unread (``bad(path, what)``
    makes the one-line error), bounded even if the file grows while it is read."""
    try:
        size = path.stat().st_size
        if size > MAX_INPUT_BYTES:
            raise bad(path, f"{size / 1e6:.0f} MB is too large "
                            f"(at most {MAX_INPUT_BYTES // 2**20} MiB)")  # fmt: skip
        with path.open("rb") as f:
            data = f.read(MAX_INPUT_BYTES + 1)
    except OSError as e:
        raise bad(path, f"unreadable ({e.strerror or e})") from None
    if len(data) > MAX_INPUT_BYTES:
        raise bad(path, f"too large (more than {MAX_INPUT_BYTES // 2**20} MiB)")
    return data


class WeightsFolder:
    """The one checked reader of the project's NumPy checkpoints (the learned planner, the
    learned eyes): a folder holding a JSON description (``config``) and ``weights.npz``.

    :meth:`digest` checks the folder and both files (each bounded) and returns their
    bytes' digest, the key a loader caches on; :meth:`read` parses the description
    (``check(path, cfg)`` checks its fields), then reads exactly the arrays
    ``shapes(cfg)`` names, each of its shape, all finite, nothing unpickled. Every
    failure is one :class:`InputError` line: ``PATH: not a NOUN: what``.
    """

    WEIGHTS = "weights.npz"

    def __init__(self, noun: str, config: str, check, shapes, dtype=np.float64) -> None:
        self.noun, self.config, self.check, self.shapes, self.dtype = (
            noun, config, check, shapes, dtype
        )  # fmt: skip

    def bad(self, path: Path, what: str) -> InputError:
        return InputError(f"{path}: not a {self.noun}: {what}")

    def digest(self, folder: Path) -> str:
        holds = f"{self.config} and {self.WEIGHTS}"
        if not folder.exists():
            raise InputError(f"{folder}: no such folder; a {self.noun} is a folder of {holds}")
        if not folder.is_dir():
            raise InputError(f"{folder}: not a folder; a {self.noun} is a folder of {holds}")
        h = hashlib.sha256()
        for name in (self.config, self.WEIGHTS):
            p = folder / name
            if not p.is_file():
                raise self.bad(folder, f"{name} is missing (it holds {holds})")
            h.update(bounded_bytes(p, self.bad))
        return h.hexdigest()

    def read(self, folder: Path) -> tuple[dict, dict[str, np.ndarray]]:
        cfg_path, w_path = folder / self.config, folder / self.WEIGHTS
        try:
            cfg = json.loads(bounded_bytes(cfg_path, self.bad).decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            where = f" (line {e.lineno})" if isinstance(e, json.JSONDecodeError) else ""
            raise self.bad(cfg_path, f"unreadable JSON{where}: {e}") from None
        if not isinstance(cfg, dict):
            raise self.bad(cfg_path, f"the file holds a {type(cfg).__name__}, not a mapping")
        self.check(cfg_path, cfg)
        expected = self.shapes(cfg)
        what = f"expected the weights of this {self.noun} ({cfg_path.name})"
        try:
            # Every array by its header first (nothing decompressed): exactly the
            # architecture's arrays, each of its shape; then only those are read.
            headers = npz_headers(w_path, what)
            missing = [k for k in expected if k not in headers]
            extra = sorted(set(headers) - set(expected))
            if missing or extra:
                raise InputError(
                    f"{w_path}: {cfg_path.name} asks for {', '.join(expected)}"
                    + (f"; missing {', '.join(missing)}" if missing else "")
                    + (f"; unknown {', '.join(extra)}" if extra else "")
                )
            for k, shape in expected.items():
                if headers[k][0] != shape:
                    raise InputError(f"{w_path}: array {k} has shape {headers[k][0]}, but "
                                     f"{cfg_path.name} asks for {shape}")  # fmt: skip
            arrays = read_npz(w_path, what, expected)
        except InputError as e:
            raise self.bad(w_path, str(e).removeprefix(f"{w_path}: ")) from None
        weights = {k: np.asarray(arrays[k], self.dtype) for k in expected}
        for k, a in weights.items():
            if not np.isfinite(a).all():
                raise self.bad(w_path, f"array {k} holds NaN or infinite values")
        return cfg, weights


def save_npz(path: str | Path, samples: dict[str, np.ndarray], actions: list[str]) -> None:
    """Write samples plus the phase and action names (whole, or not at all)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part.npz")
    np.savez_compressed(
        tmp, **samples, phases=np.array(PHASE_NAMES), actions=np.array(actions, dtype=str)
    )
    tmp.replace(path)


#: A trajectory's arrays: the ones it must hold, and those it may (a run writes them all).
TRAJECTORY = {"t": ("N",), "q": ("N", 7), "gripper": ("N",)}
TRAJECTORY_OPTIONAL = {
    "qd": ("N", 7), "qdd": ("N", 7), "phase": ("N",), "action": ("N",),
    "phases": (None,), "actions": (None,),
}  # fmt: skip
REQUIRED = tuple(TRAJECTORY)


def load_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Read a ``trajectory.npz``: the arrays a trajectory has (see
    :mod:`cake_drake.geometric.trajectory`), each checked for its shape and kind; bad
    files give one clear line."""
    path = Path(path)
    expected = "expected a trajectory.npz written by python -m cake_drake.run"
    out = read_npz(
        path, expected, TRAJECTORY, TRAJECTORY_OPTIONAL, {"phases": TEXT, "actions": TEXT}
    )
    t, q = out["t"], out["q"]
    if len(t) < 4:
        raise InputError(
            f"{path}: q has shape {q.shape} for {len(t)} times; expected (N, 7) with N >= 4"
        )
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(t))):
        raise InputError(f"{path}: 't' and 'q' must be finite numbers")
    if not np.all(np.diff(t) > 0):
        raise InputError(f"{path}: times in 't' must strictly increase")
    return out
