"""DAgger: a policy trained on a recording, then rolled out, labelled by the expert, retrained.

Imitation learning goes wrong on the states a learner drifts into, where no demonstration
went (Ross et al. 2011). :func:`dagger` first trains the recipe on the recording (behaviour
cloning, :func:`cake_drake.learning.training.train.train`), then, each round:

1. rolls the current checkpoint out (:mod:`cake_drake.learning.policies.checkpoint`) for
   ``per_round`` episodes of the recording's task (``report.json``'s spec), on seeds after
   every seed the recording tried, on the local pool or on Ray
   (:func:`cake_drake.learning.parallel.imap`); at each step the expert's action is executed
   instead with probability ``beta`` (a coin drawn from the episode's seed);
2. labels every visited state with the recording's demonstrator (the closed-loop expert,
   :mod:`cake_drake.learning.policies.expert`, by default), asked at every step on the real
   observation; an episode ends where the expert is done (the goal, or no plan from the
   measured state; the closed-loop expert's repairs are unbounded here, since the
   learner's drift is not its failure), or where the task's step budget runs out;
3. writes a new LeRobot dataset, ``OUT/data/round-K``: the recording's kept episodes
   (``DATASET/episodes/ep_SEED.npz``) and every DAgger episode so far (kept in
   ``OUT/rollouts/``), each frame's ``actor`` saying who acted (0 the expert, 1 the
   learner), its ``action`` always the expert's label;
4. fine-tunes the last checkpoint on it (lerobot's ``policy.pretrained_path``: the weights
   carried on, the normalisation from the new dataset), ``round_steps`` steps; a skill
   that never sees the arm (``--inputs relative``, a perceptron trained in a fraction of
   a minute) is trained afresh on it instead.

Skills are rolled out under the expert's choice of ground action
(:class:`cake_drake.learning.skills.checkpoints.SkillsUnderExpert`): the states they
reach with no shield step around them, which are where the demonstrations lacked.
Each training has its folder in ``OUT/rounds/round-K`` (round 0: the behaviour cloning);
the last round's checkpoints are copied to ``OUT/checkpoints``, the usual place, which
``evaluate``, a run's ``!Policy {checkpoint: OUT}`` and the Gym env load as any training's
(a relative skill: its ``skill.json`` and ``weights.npz`` to ``OUT``, which
``motion.skills`` names). ``OUT/train.json`` keeps the recipe and one row per round.
"""

from __future__ import annotations

import contextlib
import json
import math
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.learning.data import dataset
from cake_drake.learning.data.recording import (
    keep_episode,
    load_episode,
    spec_from_json,
    write_whole,
)
from cake_drake.learning.parallel import imap
from cake_drake.learning.rollout import EXPERT, LEARNER_ACTED, EpisodeSpec, Teacher, rollout
from cake_drake.learning.skills.checkpoints import SKILL_LEARNER
from cake_drake.learning.training import train as training
from cake_drake.scenario import CHECKPOINT_POLICY, Training
from cake_drake.systems.policy_source import make_policy

#: What DAgger writes in its output folder: the last round's LeRobot checkpoint, or (a
#: skill that never sees the arm) its ``skill.json`` and ``weights.npz``.
DAGGER_OUTPUTS = ("checkpoints", "train.json", "rounds", "data", "rollouts")
RELATIVE_OUTPUTS = ("skill.json", "weights.npz", "train.json", "rounds", "data", "rollouts")


def dagger_outputs(inputs: str) -> tuple[str, ...]:
    """What DAgger writes for a recipe of these ``inputs``."""
    return RELATIVE_OUTPUTS if inputs == "relative" else DAGGER_OUTPUTS


def check_rounds(rounds: int, per_round: int, beta: float, round_steps: int | None) -> None:
    """DAgger's own numbers, refused in one line (exit 2) before any work."""
    if not (isinstance(rounds, int) and 1 <= rounds <= 1000):
        raise InputError(f"--dagger {rounds}: rounds of DAgger, from 1 to 1000")
    if not (isinstance(per_round, int) and 1 <= per_round <= 100_000):
        raise InputError(f"--episodes-per-round {per_round}: from 1 to 100000")
    if not (isinstance(beta, int | float) and math.isfinite(beta) and 0.0 <= beta <= 1.0):
        raise InputError(
            f"--beta {beta}: the probability that the expert's action runs, from 0 to 1"
        )
    if round_steps is not None and not 1 <= round_steps <= 10_000_000:
        raise InputError(f"--round-steps {round_steps}: a whole number, 1 to 10000000")


def source(root: Path) -> tuple[dict, EpisodeSpec, list[Path]]:
    """The recording DAgger starts from: its report, the task its episodes ran on, and its
    kept episodes' files. One line (exit 2) where there is no task to roll a policy out on
    or no episodes to append to."""
    root = Path(root)
    need = "as python -m cake_drake.record writes them"
    path = root / "report.json"
    if not path.is_file():
        raise InputError(
            f"{path}: missing; --dagger rolls the policy out on the recording's task, "
            f"named there ({need})"
        )
    report = dataset.read_report(root)
    try:
        spec = spec_from_json(report["spec"])
        seeds = [int(s) for s in report["seeds"]]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise InputError(
            f"{path}: names no task (spec) and seeds to roll a policy out on; --dagger "
            f"needs a recording {need}"
        ) from None
    files = [root / "episodes" / f"ep_{s}.npz" for s in seeds]
    gone = [f for f in files if not f.is_file()]
    if not files or gone:
        where = gone[0] if gone else root / "episodes"
        raise InputError(
            f"{where}: missing; --dagger appends to the recording's kept episodes "
            f"(episodes/ep_SEED.npz, {need})"
        )
    for _ in _episodes(files, [_row(f, s) for f, s in zip(files, seeds, strict=True)]):
        pass  # each read by the checked reader now, not after round 0 has trained
    return report, spec, files


def _rollout_one(args):
    """One DAgger episode (in a worker): the learner acts, the teacher labels."""
    spec, seed, teacher = args
    return rollout(spec, seed, record=True, teacher=teacher)


def _row(npz: Path, seed: int) -> dict:
    """A kept episode's verdict (its ``ep_SEED.json``; a success where it is unreadable:
    only successes keep their frames)."""
    try:
        return json.loads(npz.with_suffix(".json").read_text())
    except (OSError, ValueError):
        return {"seed": seed, "success": True, "reason": "goal reached", "steps": 0,
                "wall_s": 0.0, "blocks": 0}  # fmt: skip


def _episodes(paths: list[Path], rows: list[dict]):
    for path, row in zip(paths, rows, strict=True):
        yield load_episode(path, row, images=False)


def labeller(spec, beta: float) -> Teacher:
    """The recording's expert as DAgger's teacher. The classical expert relabels however
    far the learner drifts: its repairs are unbounded unless the recording's options bound
    them (``max_repairs``)."""
    options = dict(spec.options)
    if spec.policy == EXPERT:
        options.setdefault("max_repairs", None)
    return Teacher(spec.policy, options, float(beta))


def check_skill_teacher(teacher: Teacher) -> None:
    """A teacher for learned skills labels each frame with the ground action under way
    (``skill_observation()``, as the closed-loop expert does); one line (exit 2) naming
    what a teacher lacks otherwise."""
    probe = make_policy(teacher.policy, teacher.options)
    if not callable(getattr(probe, "skill_observation", None)):
        raise InputError(
            f"--dagger for skills: the teacher {teacher.policy} cannot say which ground "
            "action is under way at each step (it has no skill_observation()); learned "
            "skills are labelled per action: record with the closed-loop expert "
            "(cake_drake.learning.expert:make)"
        )


def dagger(
    root: Path,
    out: Path,
    recipe: Training,
    rounds: int,
    per_round: int,
    beta: float = 0.0,
    device: str = "auto",
    seed: int = 0,
    workers: int = 1,
    ray=None,
    weights: str | None = None,
    round_steps: int | None = None,
    log: Callable[[str], None] = print,
    final: Path | None = None,
) -> dict:
    """Behaviour cloning on the recording at ``root``, then ``rounds`` of DAgger into
    ``out`` (see the module); its summary (``out/train.json``).

    ``out`` is where the work is written: the command's staging folder, put in place of
    ``final`` (the folder the user named) only when every round has finished
    (:class:`cake_drake.outputs.files.OutputDir`); the files name ``final``."""
    root, out = Path(root), Path(out)
    check_rounds(rounds, per_round, beta, round_steps)
    report, spec, demo_files = source(root)
    relative = recipe.inputs == "relative"
    if relative:
        from cake_drake.learning.skills.train_relative import read_frames

        read_frames(root)  # the columns a relative skill learns from, each checked
    else:
        training.check(root, out, recipe, device, False)
    if recipe.inputs not in ("state", "skill", "relative"):
        raise InputError(
            f"--dagger with --inputs {recipe.inputs}: DAgger's rollouts record no images; "
            "train with --inputs state (a whole-task policy), skill or relative (learned "
            "skills)"
        )
    dataset.require_lerobot()
    teacher = labeller(spec, beta)
    skills = recipe.inputs in ("skill", "relative")
    if skills:
        check_skill_teacher(teacher)
    fit = _fit_relative if relative else _fit_lerobot
    demo_rows = [_row(f, s) for f, s in zip(demo_files, report["seeds"], strict=True)]
    tried = [int(s) for s in report["seeds"]] + [int(f["seed"]) for f in report.get("failed", [])]
    first = max(tried) + 1
    (out / "rounds").mkdir(parents=True, exist_ok=True)
    (out / "rollouts").mkdir(exist_ok=True)
    checkpoint = fit(root, out / "rounds" / "round-0", recipe, device, seed, weights=weights)
    labelled = int(report["frames"])
    log(f"round 0: {recipe.policy} trained {recipe.steps} steps on {len(demo_files)} "
        f"demonstrations ({labelled} expert-labelled frames)")  # fmt: skip
    kept_files, kept_rows, table, by_learner = [], [], [], 0
    phases = {"rollouts": 0.0, "writing": 0.0}  # seconds; the trainings' are added at the end
    for k in range(1, rounds + 1):
        learner = replace(
            spec,
            policy=SKILL_LEARNER if skills else CHECKPOINT_POLICY,
            options={**spec.action_options(), "path": str(checkpoint.resolve()),
                     "device": device},
            cameras=(),
            noise=0.0,
        )  # fmt: skip
        seeds = [first + (k - 1) * per_round + j for j in range(per_round)]
        jobs = [(learner, s, teacher) for s in seeds]
        rows, t0 = {}, time.perf_counter()
        for ep in imap(_rollout_one, jobs, workers, ray):
            rows[ep.seed] = (keep_episode(ep, out / "rollouts", failed_too=True), ep)
        phases["rollouts"] += time.perf_counter() - t0
        added = learner_frames = wins = 0
        for s in seeds:
            row, ep = rows[s]
            wins += bool(row["success"])
            if ep.actions is None:  # the expert was done before any step
                continue
            kept_files.append(out / "rollouts" / f"ep_{s}.npz")
            kept_rows.append(row)
            added += len(ep.actions)
            learner_frames += int(np.sum(ep.actors == LEARNER_ACTED))
        labelled += added
        by_learner += learner_frames
        data, t0 = out / "data" / f"round-{k}", time.perf_counter()
        frames = dataset.write(
            data,
            _episodes(demo_files + kept_files, demo_rows + kept_rows),
            spec.rate_hz,
            spec.control_mode,
            (),
        )
        write_whole(data / "report.json", json.dumps({
            **report,
            "episodes": len(demo_files) + len(kept_files),
            "frames": frames,
            "cameras": [],
            "dagger": {"round": k, "beta": beta, "learner_frames": by_learner,
                       "seeds": [r["seed"] for r in kept_rows]},
        }, indent=2) + "\n")  # fmt: skip
        phases["writing"] += time.perf_counter() - t0
        steps = round_steps or recipe.steps
        checkpoint = fit(data, out / "rounds" / f"round-{k}", replace(recipe, steps=steps),
                         device, seed + k, pretrained=checkpoint)  # fmt: skip
        line = {
            "round": k,
            "episodes": per_round,
            "frames_added": added,
            "learner_frames": learner_frames,
            "expert_labelled_frames": labelled,
            "learner_success": wins,
            "seeds": seeds,
            "steps": steps,
        }
        table.append(line)
        log(f"round {k}: {per_round} episodes, {added} frames added ({learner_frames} by "
            f"the learner, {added - learner_frames} by the expert), {labelled} "
            f"expert-labelled frames in all; the learner's rollouts reached the goal in "
            f"{wins}/{per_round} (beta {beta:g}); {'trained afresh' if relative else 'fine-tuned'} "
            f"{steps} steps")  # fmt: skip
    last = out / "rounds" / f"round-{rounds}"
    if relative:
        for name in ("skill.json", "weights.npz"):
            shutil.copy2(last / name, out / name)
    else:
        shutil.copytree(last / "checkpoints", out / "checkpoints", symlinks=True)
    for k in range(rounds + 1):  # each training's own phases (train.json), added up
        trained = json.loads((out / "rounds" / f"round-{k}" / "train.json").read_text())
        for name, seconds in trained.get("phases_s", {}).items():
            phases[name] = phases.get(name, 0.0) + seconds
    summary = {
        "dataset": str(root),
        "recipe": asdict(recipe),
        "seed": seed,
        "phases_s": {k: round(v, 3) for k, v in phases.items()},
        "dagger": {
            "rounds": table,
            "teacher": {"policy": teacher.policy, "options": teacher.options},
            "beta": beta,
            "episodes_per_round": per_round,
            "round_steps": round_steps or recipe.steps,
            "data": str(out / "data" / f"round-{rounds}"),
            "expert_labelled_frames": labelled,
        },
    }
    (out / "train.json").write_text(json.dumps(summary, indent=2) + "\n")
    if final is not None:
        _repoint(out, Path(final))
    return summary


def _fit_lerobot(data, folder, recipe, device, seed, weights=None, pretrained=None) -> Path:
    """A LeRobot policy trained on ``data`` into ``folder`` (fine-tuned from
    ``pretrained``); its checkpoint."""
    with contextlib.redirect_stdout(sys.stderr):  # lerobot's own lines: not the rounds'
        return training.train(data, folder, recipe, device, seed, weights=weights,
                              pretrained=pretrained)  # fmt: skip


def _fit_relative(data, folder, recipe, device, seed, weights=None, pretrained=None) -> Path:
    """A skill that never sees the arm trained afresh on ``data`` (every frame so far:
    DAgger's aggregate) into ``folder``, which it is; its training's time is kept in
    ``folder/train.json`` as a LeRobot training's is."""
    from cake_drake.learning.skills.train_relative import train_recipe

    folder = Path(folder)
    folder.mkdir(parents=True)
    info = train_recipe(data, folder, recipe, seed, progress=lambda line: None)
    (folder / "train.json").write_text(
        json.dumps({"frames": info["frames"], "phases_s": {"training": info["minutes"] * 60}})
        + "\n"
    )
    return folder


def _repoint(staging: Path, final: Path) -> None:
    """Name ``final`` instead of ``staging`` in the JSON files written there (the
    trainings' records and LeRobot's configs), before they are put in place."""
    old, new = json.dumps(str(staging))[1:-1], json.dumps(str(final))[1:-1]
    for path in staging.rglob("*.json"):
        text = path.read_text(encoding="utf-8")
        if old in text:
            path.write_text(text.replace(old, new), encoding="utf-8")
