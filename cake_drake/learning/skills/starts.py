"""Start pools for ``CakeDrake/Skill-v0``: the Diagram's state where an action began,
saved once and restored by ``reset``, so that no episode replays the actions before it.

A start is every piece of state the action's episode reads: the time, the plant's
positions and velocities and the controller's and the skills' vectors (the context's
continuous and discrete state), the execution monitor's and the skill system's own
state (:class:`~cake_drake.systems.monitor.MonitorState`,
:class:`~cake_drake.systems.skills.SkillProgress`), the lead skill's memory where it has
one, and the problem it belongs to (its seed and cube count, which rebuild the same
Diagram). The plant's step memory (what its sampled output ports report) is not saved:
the first step after a restore recomputes it before anything reads it.

A pool is one JSON file (numbers written exactly as Python reads them back) holding the
settings of the environment that drew it and the SHA-256 of its lead skill's files:
:func:`read` refuses, in one line naming the file, a pool of another skill or of another
task's cubes, masses, controller or rates, an empty, truncated or non-finite one.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, fields, is_dataclass
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError, OutputError
from cake_drake.formats import MAX_INPUT_BYTES, check_format, read_json_mapping
from cake_drake.policy.observations import SkillContext
from cake_drake.symbolic.pddl import GroundAction
from cake_drake.systems.monitor import MonitorState
from cake_drake.systems.skills import SkillProgress

KIND = "cake_drake start pool"
FORMAT = 1
#: The types a start's state may hold (nothing else is ever built from a file).
TYPES = {t.__name__: t for t in (GroundAction, SkillContext, MonitorState, SkillProgress)}
#: The most starts one pool holds.
MAX_STARTS = 2_000


def digest(folder: str | Path) -> str:
    """The SHA-256 of a skill folder's files (names and contents, in sorted order)."""
    h = hashlib.sha256()
    for path in sorted(p for p in Path(folder).rglob("*") if p.is_file()):
        h.update(path.relative_to(folder).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def encode(value):
    """``value`` as JSON: the types of :data:`TYPES`, tuples, frozensets, arrays and
    mappings spelled out so :func:`decode` gives back an equal value."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float | np.floating):
        return float(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.ndarray):
        return {"array": value.tolist(), "dtype": value.dtype.str}
    if isinstance(value, tuple):
        return {"tuple": [encode(v) for v in value]}
    if isinstance(value, list):
        return [encode(v) for v in value]
    if isinstance(value, frozenset):
        return {"frozenset": sorted((encode(v) for v in value), key=json.dumps)}
    if isinstance(value, dict):
        return {"items": [[encode(k), encode(v)] for k, v in value.items()]}
    if is_dataclass(value) and type(value).__name__ in TYPES:
        named = {f.name: encode(getattr(value, f.name)) for f in fields(value)}
        return {"type": type(value).__name__, "fields": named}
    raise TypeError(f"a start cannot hold a {type(value).__name__}")


def decode(value, where: str):
    """The value :func:`encode` wrote; one line naming ``where`` for anything else."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise InputError(f"{where}: holds {value}; a start's numbers are finite")
        return value
    if isinstance(value, list):
        return [decode(v, where) for v in value]
    if isinstance(value, dict):
        keys = set(value)
        try:
            if keys == {"array", "dtype"}:
                out = np.asarray(value["array"], np.dtype(value["dtype"]))
                if out.dtype.kind == "f" and not np.all(np.isfinite(out)):
                    raise InputError(f"{where}: holds a non-finite number; a start's are finite")
                return out
            if keys == {"tuple"}:
                return tuple(decode(v, where) for v in value["tuple"])
            if keys == {"frozenset"}:
                return frozenset(decode(v, where) for v in value["frozenset"])
            if keys == {"items"}:
                return {decode(k, where): decode(v, where) for k, v in value["items"]}
            if keys == {"type", "fields"} and value["type"] in TYPES:
                kind = TYPES[value["type"]]
                given = {k: decode(v, where) for k, v in value["fields"].items()}
                return kind(**given)
        except (TypeError, ValueError) as e:
            raise InputError(f"{where}: unreadable ({e}); expected a start pool's state") from None
    raise InputError(f"{where}: holds {str(value)[:40]!r}; expected a start pool's state")


@dataclass(frozen=True)
class Start:
    """One start: the problem it belongs to and the Diagram's state there."""

    seed: int  # the problem's seed (and its world's: masses, placement)
    blocks: int
    time: float
    continuous: np.ndarray
    discrete: tuple[np.ndarray, ...]
    abstract: dict  # index of the context's abstract state -> its value
    lead: dict | None  # the lead skill's memory (None: it has none to give)


def capture(context, seed: int, blocks: int, lead) -> Start:
    """The start ``context`` (a Diagram's root context) stands at."""
    abstract = {}
    for i in range(context.num_abstract_states()):
        held = context.get_abstract_state(i)
        if type(held).__name__.startswith("Value"):  # a Python object's (the plant's is not)
            value = held.get_value()
            if type(value).__name__ in TYPES:
                abstract[i] = value
    state = context.get_discrete_state()
    memory = lead.memory() if hasattr(lead, "memory") else None
    return Start(
        seed=int(seed), blocks=int(blocks), time=float(context.get_time()),
        continuous=context.get_continuous_state_vector().CopyToVector(),
        discrete=tuple(state.get_vector(i).CopyToVector() for i in range(state.num_groups())),
        abstract=abstract, lead=memory,
    )  # fmt: skip


def restore(context, start: Start, lead) -> None:
    """Put ``start`` into ``context`` (a fresh context of the same problem's Diagram)."""
    context.SetTime(start.time)
    context.SetContinuousState(start.continuous)
    for i, values in enumerate(start.discrete):
        context.SetDiscreteState(i, values)
    for i, value in start.abstract.items():
        context.get_mutable_abstract_state(i).set_value(value)
    if start.lead is not None and hasattr(lead, "restore"):
        lead.restore(start.lead)
    else:
        lead.reset()


def write(path: str | Path, settings: dict, skill_digest: str, starts: list[Start]) -> None:
    """The pool, whole or not at all."""
    path = Path(path)
    rows = [
        {"seed": s.seed, "blocks": s.blocks, "time": s.time,
         "continuous": s.continuous.tolist(), "discrete": [d.tolist() for d in s.discrete],
         "abstract": {str(i): encode(v) for i, v in s.abstract.items()},
         "lead": encode(s.lead)}
        for s in starts
    ]  # fmt: skip
    body = {"kind": KIND, "format": FORMAT, "skill_digest": skill_digest,
            "settings": settings, "starts": rows}  # fmt: skip
    part = path.with_name(path.name + ".part")
    try:
        part.write_text(json.dumps(body), encoding="utf-8")
        part.replace(path)
    except OSError as e:
        part.unlink(missing_ok=True)
        raise OutputError(f"{path}: the start pool could not be written ({e.strerror})") from None


def read(path: str | Path, settings: dict, skill_digest: str, skill: str) -> list[Start]:
    """The starts of the pool at ``path``, checked against the environment that will
    restore them (its ``settings`` and its skill's digest); one line otherwise."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as e:
        raise InputError(f"{path}: unreadable ({e.strerror}); expected a start pool") from None
    if size > MAX_INPUT_BYTES:
        raise InputError(f"{path}: {size} bytes; a start pool is at most {MAX_INPUT_BYTES}")
    pool = read_json_mapping(path, "a start pool")
    if pool.get("kind") != KIND:
        raise InputError(f"{path}: field 'kind' is {pool.get('kind')!r:.40}; expected {KIND!r} "
                         "(python -m cake_drake.record SPEC --starts FILE writes one)")  # fmt: skip
    check_format(pool, path, (FORMAT,))
    if pool.get("skill_digest") != skill_digest:
        raise InputError(f"{path}: drawn with another lead skill than {skill} (its files' "
                         "SHA-256 differs); record the pool again with this skill")  # fmt: skip
    theirs = pool.get("settings")
    if not isinstance(theirs, dict):
        raise InputError(f"{path}: field 'settings' must be a mapping")
    for name, ours in settings.items():
        if theirs.get(name) != ours:
            raise InputError(f"{path}: settings.{name} is {theirs.get(name)!r:.60}; this "
                             f"environment's is {ours!r:.60} (record the pool for it)")  # fmt: skip
    rows = pool.get("starts")
    if not isinstance(rows, list) or not rows:
        raise InputError(f"{path}: field 'starts' holds no start; a pool holds 1 or more")
    if len(rows) > MAX_STARTS:
        raise InputError(f"{path}: {len(rows)} starts; a pool holds at most {MAX_STARTS}")
    return [_start(row, f"{path}: starts[{k}]") for k, row in enumerate(rows)]


def _start(row, where: str) -> Start:
    want = {"seed", "blocks", "time", "continuous", "discrete", "abstract", "lead"}
    if not isinstance(row, dict) or set(row) != want:
        raise InputError(f"{where}: expected the fields {', '.join(sorted(want))}")
    seed, blocks, t = row["seed"], row["blocks"], row["time"]
    if type(seed) is not int or type(blocks) is not int or not 1 <= blocks <= 12:
        raise InputError(f"{where}: seed and blocks must be whole numbers (blocks 1 to 12)")
    if not isinstance(t, float | int) or not math.isfinite(t) or t < 0:
        raise InputError(f"{where}: time must be a finite number of seconds from 0")

    def vector(values, name):
        try:
            out = np.asarray(values, np.float64)
        except (TypeError, ValueError):
            out = np.empty((0, 0))
        if out.ndim != 1 or not np.all(np.isfinite(out)):
            raise InputError(f"{where}.{name}: expected a list of finite numbers")
        return out

    discrete = row["discrete"]
    if not isinstance(discrete, list):
        raise InputError(f"{where}.discrete: expected a list of the state's groups")
    abstract = row["abstract"]
    if not isinstance(abstract, dict) or not all(k.isdigit() for k in abstract):
        raise InputError(f"{where}.abstract: expected abstract states by index")
    lead = decode(row["lead"], f"{where}.lead")
    if lead is not None and not isinstance(lead, dict):
        raise InputError(f"{where}.lead: expected the lead skill's memory, a mapping")
    return Start(
        seed=seed, blocks=blocks, time=float(t),
        continuous=vector(row["continuous"], "continuous"),
        discrete=tuple(vector(d, f"discrete[{i}]") for i, d in enumerate(discrete)),
        abstract={int(k): decode(v, f"{where}.abstract.{k}") for k, v in abstract.items()},
        lead=lead,
    )  # fmt: skip


def settings_of(env) -> dict:
    """What a pool must share with the environment restoring it: whatever shapes the
    problems, the world and the Diagram's state (not the reward, nor the budget)."""
    controller = env.controller
    if controller is not None and is_dataclass(controller):
        controller = {"type": type(controller).__name__, **asdict(controller)}
    return json.loads(json.dumps({
        "blocks": list(env.blocks), "tall": env.tall, "actions": list(env.kinds),
        "placement": list(env.placement), "cube_mass_range_kg": list(env.cube_mass_range_kg),
        "controller": controller, "rate_hz": env.rate_hz, "time_step": env.time_step,
        "planner": env.planner, "horizon": env.horizon,
    }, default=repr))  # fmt: skip
