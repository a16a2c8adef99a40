"""An RL training's folder as a policy: its one checked reader and :class:`RlPolicy`.

The folder (written by ``python -m cake_drake.train --rl``,
:mod:`cake_drake.learning.training.rl`) holds ``model.zip`` (Stable-Baselines3's),
``rl.json`` (what it is: algorithm, action space, the bound, the base and its weights'
digest, the reward, the training's figures), ``progress.csv`` (one row an episode) and
``curve.png`` (success and return against environment steps).

What the learner reads and what its answer means, the same in training
(:class:`cake_drake.learning.training.rl.LearnerEnv`) and here:

- it reads one vector: the Gym env's ``state`` (22) and ``environment_state`` (240: the
  cubes' poses and the goal), and, for a residual, the base policy's action;
- it answers with numbers from -1 to 1, one per number of the action, scaled by the
  recipe's bound and added to a base action:

  - **a residual** (``base``: a frozen policy's checkpoint, ResiP's recipe): the base
    acts from its own inputs (its cameras too) and the learner adds at most
    ``residual_scale`` to each joint target (rad; ``ee_delta``: to each motion of the
    hand) and ``residual_gripper`` to the gripper's command. The learner's last layer
    starts at zero: before training, the residual changes nothing.
  - **from scratch** (no base): the base is "hold still" (``joint_position``: the
    joints as measured, a joint-delta action; ``ee_delta``: no motion), the bound the
    same, and the gripper's command the learner's own, over its whole range.

:func:`read_rl` is the folder's one checked reader; :class:`RlPolicy` runs it wherever a
checkpoint runs (``evaluate DIR``, a run's ``!Policy {checkpoint: DIR}``, the Gym env's
policy plug-in), through :mod:`cake_drake.learning.policies.checkpoint`.
"""

from __future__ import annotations

import hashlib
import zipfile
from functools import lru_cache
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.formats import check_format, read_json_mapping
from cake_drake.geometric.ik import Kinematics
from cake_drake.learning.policies.lerobot_checkpoint import (
    CheckpointPolicy,
    camera_features,
    model_folder,
    read_checkpoint,
)
from cake_drake.learning.policies.lerobot_checkpoint import check_folder as check_base
from cake_drake.policy import spaces
from cake_drake.scenario import resolve_path

FILE = "rl.json"
MODEL = "model.zip"
PROGRESS = "progress.csv"
CURVE = "curve.png"
FILES = (FILE, MODEL, PROGRESS, CURVE)
ALGORITHMS = ("ppo", "sac")
#: The action spaces a learner answers in (a chunk is not learned from a reward).
SPACES = ("joint_position", "ee_delta")
#: What the learner reads besides a base's action: state (22) and environment_state (240).
OBSERVATION_SIZE = 22 + 240
FORMAT = 1
#: The layer's label in a run's ``layers`` and the tables.
KIND_LABELS = {"residual": "imitation + RL residual", "scratch": "RL from scratch"}


# --- what the learner reads and what its answer does ----------------------------------------


def observation_vector(observation) -> np.ndarray:
    """The learner's input from a Gym observation (``state``, ``environment_state``) or
    the policy slot's (``observation.*``): 262 float32 numbers."""
    if "observation.state" in observation:
        parts = [observation[k] for k in ("observation.state", "observation.velocity",
                                          "observation.ee_pose",
                                          "observation.environment_state")]  # fmt: skip
    else:
        parts = [observation["state"], observation["environment_state"]]
    return np.concatenate([np.asarray(p, np.float32).ravel() for p in parts])


def _joints(observation) -> np.ndarray:
    if "observation.state" in observation:
        return np.asarray(observation["observation.state"], np.float64)[:7]
    return np.asarray(observation["state"], np.float64)[:7]


class Composer:
    """A learner's answer (-1 to 1 a number) as an action of ``space``: added to the
    base's action within ``bound``, or (no base) to "hold still"."""

    def __init__(self, space: str, scale: float, gripper: float, residual: bool, low, high):
        self.space, self.residual = space, residual
        self.low, self.high = np.asarray(low, np.float64), np.asarray(high, np.float64)
        size = len(self.low)
        self.bound = np.r_[np.full(size - 1, scale), gripper]

    def action(self, answer, observation, base_action=None) -> np.ndarray:
        a = np.clip(np.asarray(answer, np.float64), -1.0, 1.0)
        if self.residual:
            out = np.asarray(base_action, np.float64) + self.bound * a
        else:
            hold = _joints(observation) if self.space == "joint_position" else np.zeros(6)
            gripper = self.low[-1] + (a[-1] + 1.0) / 2.0 * (self.high[-1] - self.low[-1])
            out = np.r_[hold + self.bound[:-1] * a[:-1], gripper]
        return np.clip(out, self.low, self.high)


def digest(folder: Path) -> str:
    """The SHA-256 of a checkpoint's weights: what a residual names its base by."""
    h = hashlib.sha256()
    with open(Path(folder) / "model.safetensors", "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# --- the folder, read back --------------------------------------------------------------


def is_rl(path) -> bool:
    """Whether ``path`` is an RL training's folder (it holds ``rl.json``)."""
    return (Path(path) / FILE).is_file()


def read_rl(folder) -> dict:
    """The one checked reader of an RL folder: ``rl.json`` checked against itself and
    against ``model.zip`` (a Stable-Baselines3 archive); one line naming the file and
    the field otherwise. A residual's base is checked where it runs (:func:`check_folder`)."""
    folder = Path(folder)
    path = folder / FILE
    info = read_json_mapping(path, "an RL checkpoint's description")
    check_format(info, path, (FORMAT,))
    want = {
        "kind": lambda v: v in KIND_LABELS,
        "algorithm": lambda v: v in ALGORITHMS,
        "action_space": lambda v: v in SPACES,
        "observation_size": lambda v: isinstance(v, int) and v >= OBSERVATION_SIZE,
        "action_size": lambda v: isinstance(v, int) and 2 <= v <= 8,
        "residual_scale": lambda v: isinstance(v, int | float) and 0 < v <= 1,
        "residual_gripper": lambda v: isinstance(v, int | float) and 0 <= v <= 0.08,
    }
    for name, ok in want.items():
        if name not in info or isinstance(info[name], bool) or not ok(info[name]):
            raise InputError(f"{path}: field {name!r} is {info.get(name)!r:.40}, not valid")
    residual = info["kind"] == "residual"
    if info["observation_size"] != OBSERVATION_SIZE + (info["action_size"] if residual else 0):
        raise InputError(f"{path}: observation_size {info['observation_size']} does not fit "
                         f"a {info['kind']} over {info['action_size']} actions")  # fmt: skip
    base = info.get("base")
    if residual and not (
        isinstance(base, dict) and isinstance(base.get("path"), str)
        and isinstance(base.get("sha256"), str)
    ):  # fmt: skip
        raise InputError(f"{path}: a residual names its base (field 'base': path and sha256)")
    model = folder / MODEL
    try:
        with zipfile.ZipFile(model) as z:
            names = set(z.namelist())
    except (OSError, zipfile.BadZipFile) as e:
        raise InputError(f"{model}: not a readable Stable-Baselines3 archive ({e})") from None
    if not {"data", "policy.pth"} <= names:
        raise InputError(f"{model}: not a Stable-Baselines3 archive (no data and policy.pth)")
    return info


def check_weights(folder, info: dict) -> None:
    """Refuse ``model.zip`` whose network cannot act as ``rl.json`` says, before any
    episode: weights that Stable-Baselines3's own loader cannot read (the network by
    PyTorch's ``weights_only`` load), no policy, spaces of other sizes, or values that
    are not finite. Remembered by the file's bytes."""
    model = Path(folder) / MODEL
    h = hashlib.sha256()
    with open(model, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    _checked_weights(str(model), h.hexdigest(), info["observation_size"], info["action_size"])


@lru_cache(maxsize=8)
def _checked_weights(model: str, sha256: str, observation_size: int, action_size: int) -> None:
    del sha256  # the cache's key: the same bytes are the same weights
    # Stable-Baselines3 (torch: seconds, the rl extra) only where an RL folder is read.
    from stable_baselines3.common.save_util import load_from_zip_file

    try:
        data, params, _ = load_from_zip_file(model, device="cpu", print_system_info=False)
    except Exception as e:  # noqa: BLE001 - a user's file: any failure to read it is bad input
        first = (str(e).strip().splitlines() or [""])[0][:160]
        raise InputError(f"{model}: its weights cannot be read ({type(e).__name__}: "
                         f"{first})") from None  # fmt: skip
    policy = (params or {}).get("policy")
    if not isinstance(policy, dict) or not policy:
        raise InputError(f"{model}: holds no policy network (policy.pth)")
    spaces_said = {
        "observation_space": (observation_size,),
        "action_space": (action_size,),
    }
    for name, shape in spaces_said.items():
        got = getattr((data or {}).get(name), "shape", None)
        if got != shape:
            raise InputError(f"{model}: its {name} is {got}, where {FILE} says {shape}")
    for key, tensor in policy.items():
        values = getattr(tensor, "detach", None)
        if values is None:
            raise InputError(f"{model}: policy entry {key!r} is not a tensor")
        if not bool(values().isfinite().all()):
            raise InputError(f"{model}: policy entry {key!r} holds NaN or infinite values")


def check_folder(path, action_space: str, device: str = "auto", cameras=None) -> dict:
    """Refuse, before anything is built, an RL folder that cannot run here: unreadable,
    another action space than the run's, a residual whose base is missing or is another
    policy than the one it was trained on (its weights' digest), a base that sees cameras
    the run lacks, or a device other than the CPU; ``rl.json``'s contents."""
    info = read_rl(path)
    if device not in ("auto", "cpu"):
        raise InputError(f"{path}: an RL policy acts on the CPU; device {device!r} is not for it")
    check_weights(path, info)
    if info["action_space"] != action_space:
        raise InputError(f"{path}: learned in {info['action_space']}; the run's action space "
                         f"is {action_space}")  # fmt: skip
    if info["kind"] == "residual":
        base = resolve_path(info["base"]["path"])
        if not base.exists():
            raise InputError(f"{path}: its base {info['base']['path']} is not there")
        if is_rl(base):
            raise InputError(f"{path}: its base {base} is an RL folder, not a learned policy")
        folder = check_base(base, action_space, "cpu", cameras)
        if digest(folder) != info["base"]["sha256"]:
            raise InputError(
                f"{path}: a residual for another base policy (the weights at "
                f"{info['base']['path']} are not the ones it was trained on)"
            )
    return info


def base_cameras(path) -> dict:
    """The cameras an RL folder's policy sees: its base's (none from scratch)."""
    info = read_rl(path)
    if info["kind"] != "residual":
        return {}
    return camera_features(read_checkpoint(model_folder(resolve_path(info["base"]["path"]))))


def describe(path) -> str:
    """The learned layer as a run's ``layers`` names it."""
    info = read_rl(path)
    return f"{KIND_LABELS[info['kind']]}, {info['algorithm'].upper()}"


class RlPolicy:
    """An RL folder as a policy plug-in: the base (a residual's) and the learner, acting
    deterministically (the learner's mean answer)."""

    def __init__(self, path: str, device: str = "auto") -> None:
        self.path = Path(path)
        self.info = read_rl(self.path)
        self._device = device
        self._model = self.base = None

    def _load(self, task) -> None:
        info = self.info
        if info["kind"] == "residual":
            self.base = CheckpointPolicy(str(resolve_path(info["base"]["path"])), "cpu")
        # Stable-Baselines3 (torch: seconds, the rl extra) only when the policy first acts.
        if info["algorithm"] == "ppo":
            from stable_baselines3 import PPO as Algorithm
        else:
            from stable_baselines3 import SAC as Algorithm
        self._model = Algorithm.load(self.path / MODEL, device="cpu")
        shape = self._model.observation_space.shape
        if shape != (info["observation_size"],) or self._model.action_space.shape != (
            info["action_size"],
        ):
            raise InputError(f"{self.path / MODEL}: its network reads {shape} and answers "
                             f"{self._model.action_space.shape}, not what {FILE} says")  # fmt: skip
        kin = Kinematics()
        low, high = spaces.bounds(info["action_space"], {}, kin.lower, kin.upper)
        self.composer = Composer(
            info["action_space"], info["residual_scale"], info["residual_gripper"],
            self.base is not None, low, high,
        )  # fmt: skip

    def reset(self, task, seed: int) -> None:
        space = getattr(task, "action_space", "joint_position")
        if space != getattr(self, "_checked", None):  # the base's digest: once, not per episode
            check_folder(self.path, space, self._device)
            self._checked = space
        if self._model is None:
            self._load(task)
        if self.base is not None:
            self.base.reset(task, seed)

    def act(self, observation) -> np.ndarray:
        v = observation_vector(observation)
        base = None
        if self.base is not None:
            base = np.asarray(self.base.act(observation), np.float64)
            v = np.r_[v, base.astype(np.float32)]
        answer, _ = self._model.predict(v, deterministic=True)
        return self.composer.action(answer, observation, base)
