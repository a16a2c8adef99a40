"""A skill with an RL residual: a relative skill's hand moves, corrected by a learner.

The folder (written by ``python -m cake_drake.train --rl SUITE --name TASK`` for a task
whose ``motion.skills`` is a relative skill, :mod:`cake_drake.learning.training.rl`)
holds ``model.zip`` (Stable-Baselines3's), ``skill_rl.json`` (what it is: the algorithm,
the bound, the base skill by path and by its weights' SHA-256, the reward, the
training's figures), ``progress.csv`` and ``curve.png``. It runs wherever a skill runs
(``motion.skills``, ``evaluate DIR``), as the same kind of thing: it never sees the arm.

What the learner reads and what its answer means, the same in training
(``CakeDrake/Skill-v0``) and here: it reads the skill's own input
(``observation.relative``, 14 numbers) and the base skill's answer (7), and answers four
numbers from -1 to 1, each scaled by ``residual_scale`` (m; rad for the turn) and added
to the base's move of the hand (dx, dy, dz, dyaw); the gripper's decision, roll and
pitch stay the base's. The learner's last layer starts at zero: before any training the
skill is its base, number for number.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.formats import check_format, read_json_mapping
from cake_drake.learning.policies.rl import ALGORITHMS, CURVE, MODEL, PROGRESS, check_weights
from cake_drake.learning.skills import relative as relative_skill
from cake_drake.policy.observations import RELATIVE_SIZE
from cake_drake.scenario import portable_path, resolve_path

FILE = "skill_rl.json"
FILES = (FILE, MODEL, PROGRESS, CURVE)
FORMAT = 1
KIND = "skill_residual"
#: The base's answer the learner corrects: dx dy dz and dyaw of ee_delta's seven numbers.
MOVES = (0, 1, 2, 5)
ACTION_SIZE = len(MOVES)
OBSERVATION_SIZE = RELATIVE_SIZE + 7
#: The largest correction a step (m, rad) a folder may say.
MAX_SCALE = 0.05


def compose(base_action, answer, scale: float) -> np.ndarray:
    """The skill's action: the base's, with ``answer`` (clipped to -1..1) x ``scale``
    added to its moves of the hand."""
    out = np.array(base_action, np.float64, copy=True)
    out[list(MOVES)] += scale * np.clip(np.asarray(answer, np.float64), -1.0, 1.0)
    return out


def learner_input(relative, base_action) -> np.ndarray:
    """What the learner reads: the skill's input and the base's answer, 21 float32."""
    return np.r_[np.asarray(relative, np.float32).ravel(), np.asarray(base_action, np.float32)]


def digest(folder: str | Path) -> str:
    """The SHA-256 of a relative skill's weights: what a residual names its base by."""
    h = hashlib.sha256()
    with open(Path(folder) / "weights.npz", "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read(folder: str | Path) -> dict:
    """The one checked reader: ``skill_rl.json`` against itself and ``model.zip``'s
    network; one line naming the file and the field otherwise."""
    folder = Path(folder)
    path = folder / FILE
    info = read_json_mapping(path, "a skill residual's description")
    check_format(info, path, (FORMAT,))
    want = {
        "kind": lambda v: v == KIND,
        "algorithm": lambda v: v in ALGORITHMS,
        "observation_size": lambda v: v == OBSERVATION_SIZE,
        "action_size": lambda v: v == ACTION_SIZE,
        "residual_scale": lambda v: isinstance(v, int | float) and 0 < v <= MAX_SCALE,
        "base": lambda v: isinstance(v, dict) and isinstance(v.get("path"), str)
        and isinstance(v.get("sha256"), str),
    }  # fmt: skip
    for name, ok in want.items():
        if name not in info or isinstance(info[name], bool) or not ok(info[name]):
            raise InputError(f"{path}: field {name!r} is {info.get(name)!r:.60}, not valid")
    model = folder / MODEL
    if not model.is_file():
        raise InputError(f"{model}: missing (the learner's network)")
    check_weights(folder, info)
    return info


def check_folder(path: str | Path, **needs) -> dict:
    """:func:`read`, and the base there, a skill that never sees the arm, with the weights
    the residual was trained on (its digest)."""
    info = read(path)
    base = resolve_path(info["base"]["path"])
    if not (base / "skill.json").is_file():
        raise InputError(f"{path}: its base {info['base']['path']} is not a skill that never "
                         "sees the arm (no skill.json there)")  # fmt: skip
    relative_skill.check_folder(base)
    if digest(base) != info["base"]["sha256"]:
        raise InputError(f"{path}: a residual for another base skill (the weights at "
                         f"{info['base']['path']} are not the ones it was trained on)")  # fmt: skip
    return info


class ResidualSkill:
    """The folder as :class:`cake_drake.systems.skills.LearnedSkills` asks a skill:
    ``reset()`` at each new action, ``act(observation)`` -> ee_delta's 7 numbers."""

    action_space = "ee_delta"
    free_quarter_turns = True  # as its base: it reads the base's input and answer alone

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.info = check_folder(self.path)
        self.base = relative_skill.RelativeSkill(resolve_path(self.info["base"]["path"]))
        # Stable-Baselines3 (torch: seconds, the rl extra) only where such a skill runs.
        if self.info["algorithm"] == "ppo":
            from stable_baselines3 import PPO as Algorithm
        else:
            from stable_baselines3 import SAC as Algorithm
        self.model = Algorithm.load(self.path / MODEL, device="cpu")
        self.scale = float(self.info["residual_scale"])

    def reset(self) -> None:
        self.base.reset()

    def act(self, observation) -> np.ndarray:
        base = self.base.act(observation)
        v = learner_input(observation[relative_skill.INPUT], base)
        answer, _ = self.model.predict(v, deterministic=True)
        return compose(base, answer, self.scale)


def describe(path: str | Path) -> str:
    """What the skill at ``path`` is, for a run's ``layers``."""
    info = read(path)
    base = portable_path(resolve_path(info["base"]["path"]))
    return (
        f"imitation + RL residual ({info['algorithm'].upper()}) on the hand's moves, reads "
        f"the action from the hand (never the arm): base {base}"
    )


def make(path: str | Path, **options) -> ResidualSkill:
    """The loader :mod:`cake_drake.artifacts` names for this kind."""
    return ResidualSkill(path)


__all__ = ["FILES", "ResidualSkill", "check_folder", "compose", "describe", "make", "read"]
