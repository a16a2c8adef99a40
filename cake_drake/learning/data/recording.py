"""Recording demonstrations and replaying them: loops of episodes.

``record``: episodes of a demonstrator policy (the classical cake as a policy by default)
on seeded problems, each finished episode kept at once in ``OUT/episodes/`` (so an
interrupted recording keeps what finished and ``resume`` runs only the rest); the
successful ones then become one LeRobot dataset in ``OUT`` (``meta/``, ``data/``,
``videos/``: :mod:`cake_drake.learning.data.dataset`), written in seed order whatever the
workers, and ``OUT/report.json`` says what was recorded and why the others failed.

With ``spec.noise`` (DART) each executed action is the demonstrator's plus seeded noise
(:func:`cake_drake.learning.rollout.noise_scale`); the dataset's ``action`` is the
demonstrator's own, the label, and ``episodes/ep_SEED.npz`` keeps what ran as
``executed``.

``replay_check``: every episode's actions (a noisy recording's executed ones) fed open
loop through the same environment from the same seed; the fraction that builds the goal
again.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError, OutputError
from cake_drake.formats import MAX_NPZ_ARRAY_BYTES, TEXT, npz_headers, read_npz
from cake_drake.learning.data import dataset
from cake_drake.learning.parallel import imap, map_ordered
from cake_drake.learning.rollout import (
    EXPERT,
    FRAMES,
    Episode,
    EpisodeSpec,
    check_noise,
    replay,
    rollout,
)
from cake_drake.outputs.files import check_output_folder, claim_folder
from cake_drake.policy.observations import GROUND_ACTION_SIZE, NO_GROUND_ACTION, SKILL_SIZE
from cake_drake.scenario import (
    ACT_BUDGET_S,
    Policy,
    load_scenario,
    resolve_path,
    scenario_names,
)
from cake_drake.world.cameras import default_cameras
from cake_drake.world.scene import CUBE_MASS

RECORD_OUTPUTS = ("meta", "data", "videos", "episodes", "report.json")


def learning_tasks(path) -> list[str]:
    """The names in a scenario file that are learning tasks: a ``!Policy`` whose factory
    demonstrates (the expert), not a run of a trained checkpoint or of the planner."""
    out = []
    for name in scenario_names(path):
        ref = load_scenario(path, name).reference
        if isinstance(ref, Policy) and ref.factory and not ref.checkpoint:
            out.append(name)
    return out


def spec_from_scenario(scenario, policy: str | None = None) -> EpisodeSpec:
    """The episodes a scenario describes: its problem (``task.generate``: that many blocks,
    one problem per seed; ``task.problem``: that one), its cameras (the default two when
    it names none), and its ``!Policy`` (action space, rate, steps, the policy itself)."""
    s = scenario
    blocks, problem, tall = (3, 8), None, False
    if s.task.generate is not None:
        g = s.task.generate
        blocks, tall = g.blocks, g.tall
        others = {"style": g.style != "exercise", "partial": g.partial,
                  "max_height": g.max_height is not None,
                  "goal_max_height": g.goal_max_height is not None}  # fmt: skip
        unused = [name for name, set_ in others.items() if set_]
        if unused:
            raise InputError(
                f"task.generate.{unused[0]}: a learning task's episodes are generated from "
                "blocks and tall alone (one problem per seed); leave the others unset"
            )
    elif s.task.problem:
        problem = str(resolve_path(s.task.problem))
    ref = s.reference
    placement = (s.world.placement.xy, s.world.placement.yaw_deg)
    spec = EpisodeSpec(
        blocks=blocks,
        problem=problem,
        cameras=tuple(s.cameras or default_cameras()),
        placement=placement,
        tall=tall,
        # The cubes' mass as the task says it: a range drawn per episode, or one mass.
        cube_mass_range_kg=tuple(float(m) for m in s.world.cube_mass_range_kg)
        or ((s.world.cube_mass_kg,) * 2 if s.world.cube_mass_kg != CUBE_MASS else ()),
        controller=s.controller,
    )
    if isinstance(ref, Policy):
        spec = replace(
            spec,
            control_mode=ref.action_space,
            rate_hz=ref.rate_hz,
            max_steps=ref.max_steps,
            policy=ref.factory or EXPERT,
            options={k: v for k, v in (ref.options or {}).items()},
            act_budget_s=ref.act_budget_s,
        )
    if policy:
        spec = replace(spec, policy=policy, options=spec.action_options())
    return spec


# --- workers ------------------------------------------------------------------------------


def _record_one(args) -> Episode:
    """One episode, frames and all (run in a worker: a local process or a Ray node)."""
    spec, seed = args
    return rollout(spec, seed, record=True)


def keep_episode(ep: Episode, folder: Path, failed_too: bool = False) -> dict:
    """Write a finished episode into ``folder`` (its frames when it succeeded, or always
    with ``failed_too``, whole by rename; its verdict always, last); its row."""
    row = {k: v for k, v in asdict(ep).items() if k not in FRAMES}
    if (ep.success or failed_too) and ep.actions is not None:
        tmp = folder / f".ep_{ep.seed}.npz"
        with open(tmp, "wb") as f:
            np.savez(f, states=ep.states, actions=ep.actions, environment=ep.environment,
                     actors=ep.actors, executed=ep.executed, task=ep.task,
                     skills=ep.skills, grounds=ep.grounds,
                     **{f"image_{k}": v for k, v in ep.images.items()})  # fmt: skip
        os.replace(tmp, folder / f"ep_{ep.seed}.npz")
    write_whole(folder / f"ep_{ep.seed}.json", json.dumps(row) + "\n")
    return row


def write_whole(path: Path, text: str) -> None:
    """Write ``path`` whole or not at all (a temporary file, then a rename)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}")
    tmp.write_text(text)
    os.replace(tmp, path)


def _finished(cache: Path) -> dict[int, dict]:
    """The episodes of an interrupted recording that finished: seed -> row. A verdict that
    cannot be read (cut short by a crash) counts as not finished: it runs again."""
    rows = {}
    for path in cache.glob("ep_*.json"):
        try:
            row = json.loads(path.read_text())
            rows[int(row["seed"])] = row
        except (ValueError, KeyError, TypeError, OSError):
            continue
    return rows


#: What a resumed recording must share with the one it continues.
SAME_FOR_RESUME = (
    "control_mode", "rate_hz", "cameras", "problem", "blocks", "placement", "noise",
    "cube_mass_range_kg", "controller",
)  # fmt: skip


def _check_resume(cache: Path, spec: EpisodeSpec, out: Path) -> None:
    """Refuse to continue a recording made with another action space, rate, cameras,
    task or noise: one line naming what differs."""
    path = cache / "spec.json"
    if not path.is_file():
        return
    try:
        before = json.loads(path.read_text())
    except ValueError:
        return
    now = json.loads(json.dumps(_spec_json(spec)))
    before.setdefault("noise", 0.0)  # recorded before noise was a field: none
    for key in SAME_FOR_RESUME:
        if key in before and before[key] != now[key]:
            raise InputError(
                f"{out}: --resume with another {key}: the recording has {before[key]!r:.60}, "
                f"this scenario {now[key]!r:.60}; record into another --out"
            )


# --- record -------------------------------------------------------------------------------


def record(
    spec: EpisodeSpec,
    out: Path,
    seeds: list[int],
    workers: int,
    resume: bool,
    ray=None,
    task: str = "",
    training: dict | None = None,
) -> dict:
    """Record ``seeds``' episodes into the dataset at ``out`` (see the module), on a local
    pool of ``workers`` or on ``ray``; each is kept by this process as it finishes. The
    report names the ``task`` and keeps its ``training`` recipe, for ``train``."""
    dataset.require_lerobot()
    dataset.features(spec.control_mode, spec.cameras)  # a mode that cannot be recorded
    if spec.noise:
        check_noise(spec.noise, spec.control_mode)
    real = check_output_folder(out, "record", set(RECORD_OUTPUTS))
    cache = real / "episodes"
    if cache.is_dir() and any(cache.iterdir()) and not resume:
        raise InputError(
            f"{out}: holds a recording already; --resume continues it, or choose another --out"
        )
    if resume and cache.is_dir():
        _check_resume(cache, spec, out)
    claim_folder(out, "record", RECORD_OUTPUTS)
    cache.mkdir(exist_ok=True)
    write_whole(cache / "spec.json", json.dumps(_spec_json(spec)) + "\n")
    done = _finished(cache) if resume else {}
    todo = [s for s in seeds if s not in done]
    for ep in imap(_record_one, [(spec, s) for s in todo], workers, ray):
        row = keep_episode(ep, cache)
        done[ep.seed] = row
    rows = [done[s] for s in seeds]
    kept = [r for r in rows if r["success"] and (cache / f"ep_{r['seed']}.npz").is_file()]
    staging = real / f".staging-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        frames = dataset.write(
            staging / "dataset",
            (load_episode(cache / f"ep_{r['seed']}.npz", r) for r in kept),
            spec.rate_hz,
            spec.control_mode,
            spec.cameras,
        )
        report = {
            "episodes": len(kept),
            "frames": frames,
            "fps": spec.rate_hz,
            "control_mode": spec.control_mode,
            "cameras": [c.name for c in spec.cameras],
            "policy": spec.policy,
            "noise": spec.noise,
            "seeds": [r["seed"] for r in kept],
            "tried": len(rows),
            "failed": [
                {"seed": r["seed"], "reason": r["reason"], "steps": r["steps"]}
                for r in rows
                if not r["success"]
            ],
            "spec": _spec_json(spec),
            "task": task,
            "training": training or {},
        }
        (staging / "dataset" / "report.json").write_text(json.dumps(report, indent=2) + "\n")
        _install(real, staging / "dataset", ("meta", "data", "videos", "report.json"))
    except OSError as e:
        raise OutputError(f"{out}: cannot write the dataset ({e.strerror or e})") from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return report


#: What a kept episode is, for messages.
KEPT = "a kept episode (episodes/ep_SEED.npz, as python -m cake_drake.record keeps it)"
#: What a kept episode holds (``keep_episode``); ``N`` the episode's frames.
EPISODE_ARRAYS = {"states": ("N", None), "environment": ("N", None), "actions": ("N", None),
                  "task": ()}  # fmt: skip
EPISODE_OPTIONAL = {"actors": ("N",), "executed": ("N", None), "skills": ("N", None),
                    "grounds": ("N", None)}  # fmt: skip


def load_episode(path: Path, row: dict, images: bool = True) -> Episode:
    """A kept episode (``keep_episode``'s npz and row), read by the checked reader: every array's
    kind and shape checked, one line naming the file otherwise. One kept before who acted
    was recorded was the demonstrator's alone."""
    headers = npz_headers(path, KEPT, MAX_NPZ_ARRAY_BYTES)
    # An episode kept before a field was recorded holds it as None (an object array).
    optional = {k: v for k, v in EPISODE_OPTIONAL.items() if headers.get(k, ((), None))[0]}
    if images:
        optional.update({k: ("N", None, None, 3) for k in headers if k.startswith("image_")})
    z = read_npz(path, KEPT, EPISODE_ARRAYS, optional, {"task": TEXT}, MAX_NPZ_ARRAY_BYTES)
    frames = {k[6:]: v for k, v in z.items() if k.startswith("image_")}
    actions = z["actions"]
    actors = z.get("actors")
    executed = z.get("executed", actions)
    skills, grounds = _skill_frames(path, z, len(actions))
    return Episode(
        row["seed"], row["success"], row["reason"], row["steps"], row["wall_s"],
        str(z["task"]), row["blocks"], (), z["states"], z["environment"], actions, frames,
        np.zeros(len(actions), np.int64) if actors is None else actors, executed,
        skills, grounds,
    )  # fmt: skip


def _skill_frames(path: Path, z: dict, n: int) -> tuple[np.ndarray, np.ndarray]:
    """An episode's ground actions per frame; none for one kept before they were recorded."""
    if "skills" in z and z["skills"].shape == (n, SKILL_SIZE):
        if "grounds" not in z or z["grounds"].shape != (n, GROUND_ACTION_SIZE):
            raise InputError(f"{path}: array 'grounds' must have shape ({n}, "
                             f"{GROUND_ACTION_SIZE}), beside its skills")  # fmt: skip
        return z["skills"], z["grounds"]
    return np.zeros((n, SKILL_SIZE), np.float32), np.tile(NO_GROUND_ACTION, (n, 1))


def _install(real: Path, new: Path, names) -> None:
    """Put ``new``'s entries in place of ``real``'s, old ones moved aside first."""
    aside = real / f".old-{os.getpid()}"
    aside.mkdir(exist_ok=True)
    try:
        for name in names:
            if (real / name).exists():
                os.rename(real / name, aside / name)
        for name in names:
            if (new / name).exists():
                os.rename(new / name, real / name)
    finally:
        shutil.rmtree(aside, ignore_errors=True)


def _spec_json(spec: EpisodeSpec) -> dict:
    d = asdict(spec)
    d["cameras"] = [asdict(c) for c in spec.cameras]
    d["blocks"] = list(spec.blocks) if isinstance(spec.blocks, tuple) else spec.blocks
    d["placement"] = list(spec.placement)
    d["cube_mass_range_kg"] = list(spec.cube_mass_range_kg)
    c = spec.controller
    d["controller"] = None if c is None else {"type": type(c).__name__, **asdict(c)}
    return d


def spec_from_json(d: dict) -> EpisodeSpec:
    """The episodes a recording's ``report.json`` says it ran (its ``spec``), without its
    cameras: a replay, or DAgger's rollouts, judge from the poses."""
    blocks = tuple(d["blocks"]) if isinstance(d["blocks"], list) else d["blocks"]
    return EpisodeSpec(
        blocks=blocks,
        problem=d["problem"],
        control_mode=d["control_mode"],
        rate_hz=d["rate_hz"],
        max_steps=d["max_steps"],
        cameras=(),  # the replay judges from poses: no images needed
        policy=d["policy"],
        options=d["options"],
        placement=tuple(d.get("placement", (0.0, 0.0))),
        noise=float(d.get("noise", 0.0)),
        act_budget_s=float(d.get("act_budget_s", ACT_BUDGET_S)),
        tall=bool(d.get("tall", False)),
        cube_mass_range_kg=tuple(d.get("cube_mass_range_kg", ())),
        controller=_controller_from_json(d.get("controller")),
    )


def _controller_from_json(d: dict | None):
    """The controller a ``report.json`` names (``{"type": "ComputedTorque", ...}``)."""
    if not d:
        return None
    from cake_drake.dynamic import controllers

    fields = dict(d)
    kind = getattr(controllers, str(fields.pop("type", "")), None)
    if kind not in (controllers.ComputedTorque, controllers.JointPd, controllers.Pid):
        raise InputError(
            f"report.json: spec.controller {d!r:.60} is no controller a recording runs"
        )
    return kind(**fields)


# --- replay -------------------------------------------------------------------------------


def _replay_one(args) -> dict:
    spec, seed, actions = args
    return {"seed": seed, "rebuilt": replay(spec, seed, actions)}


def _ran(root: Path, seed: int, report: dict) -> np.ndarray:
    """What ran in a noisy recording's episode (its labels are the dataset's actions)."""
    path = root / "episodes" / f"ep_{seed}.npz"
    if not path.is_file():
        raise InputError(f"{path}: missing; a noisy recording replays what ran, kept there")
    return read_npz(path, KEPT, {"executed": (None, None)}, file_limit=MAX_NPZ_ARRAY_BYTES)[
        "executed"
    ]


def replay_check(root: Path, workers: int) -> dict:
    """Replay every episode of the dataset at ``root`` open loop (see the module)."""
    report = dataset.read_report(root, required=True)
    data = dataset.read(root)
    spec = spec_from_json(report["spec"])
    jobs = [
        (spec, seed, _ran(root, seed, report) if spec.noise else dataset.episode_actions(data, k))
        for k, seed in enumerate(report["seeds"])
    ]
    rebuilt = [a["rebuilt"] for a in map_ordered(_replay_one, jobs, workers)]
    return {"episodes": len(jobs), "rebuilt": sum(rebuilt), "per_episode": rebuilt}
