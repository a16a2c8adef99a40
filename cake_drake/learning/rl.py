"""Learning from a reward (``python -m cake_drake.train --rl SUITE --name TASK --out DIR``).

Stable-Baselines3's PPO (or SAC) trains on ``CakeDrake/Stack-v0`` with the task's
episodes (problem, placement, cameras, step budget), its observation and action spaces
untouched underneath, on the CPU, through Gymnasium's vectorised environments. The
recipe is the task's ``training.rl`` (:class:`cake_drake.scenario.RlRecipe`), the reward
its ``reward`` (:mod:`cake_drake.learning.rewards`).

What the learner reads and what its answer means (:class:`LearnerEnv`):

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

The folder ``DIR`` gets ``model.zip`` (Stable-Baselines3's), ``rl.json`` (what it is:
algorithm, action space, the bound, the base and its weights' digest, the reward, the
training's figures), ``progress.csv`` (one row an episode) and ``curve.png`` (success and
return against environment steps). :func:`read_rl` is its one checked reader;
:class:`RlPolicy` runs it wherever a checkpoint runs (``evaluate DIR``, a run's
``!Policy {checkpoint: DIR}``, the Gym env's policy plug-in), through
:mod:`cake_drake.learning.checkpoint`.
"""

from __future__ import annotations

import csv
import hashlib
import math
import time
import zipfile
from dataclasses import asdict, replace
from functools import lru_cache, partial
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium import spaces as gs

from cake_drake.errors import InputError
from cake_drake.formats import read_json_mapping
from cake_drake.learning.rewards import check_reward
from cake_drake.scenario import RlRecipe

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


class LearnerEnv(gymnasium.Wrapper):
    """``CakeDrake/Stack-v0`` as the learner sees it: see the module's docstring."""

    def __init__(self, env, recipe: RlRecipe, base: str = "") -> None:
        super().__init__(env)
        inner = env.unwrapped
        self.base = None
        if base:
            from cake_drake.learning.checkpoint import CheckpointPolicy

            self.base = CheckpointPolicy(base, "cpu")
        low, high = inner.action_space.low, inner.action_space.high
        self.composer = Composer(
            inner.control_mode, recipe.residual_scale, recipe.residual_gripper,
            bool(base), low, high,
        )  # fmt: skip
        size = len(low)
        self.action_space = gs.Box(-1.0, 1.0, (size,), np.float32)
        width = OBSERVATION_SIZE + (size if base else 0)
        self.observation_space = gs.Box(-np.inf, np.inf, (width,), np.float32)
        self._obs = self._base_action = None

    def _vector(self, obs) -> np.ndarray:
        self._obs = obs
        v = observation_vector(obs)
        if self.base is None:
            return v
        self._base_action = np.asarray(self.base.act(obs), np.float64)
        return np.r_[v, self._base_action.astype(np.float32)]

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        if self.base is not None:
            self.base.reset(self.env.unwrapped.policy_task, seed or 0)
        return self._vector(obs), info

    def step(self, answer):
        action = self.composer.action(answer, self._obs, self._base_action)
        obs, reward, terminated, truncated, info = self.env.step(action.astype(np.float32))
        return self._vector(obs), reward, terminated, truncated, info


def learner_env(spec, recipe: RlRecipe, base: str = ""):
    """The learner's environment of an episode spec (a module-level factory: it is
    pickled into each of the vectorised environments' processes)."""
    from stable_baselines3.common.monitor import Monitor

    from cake_drake.learning.env import StackEnv

    env = StackEnv(
        blocks=spec.blocks, problem=spec.problem,
        obs_mode="state+rgb" if spec.cameras else "state", control_mode=spec.control_mode,
        cameras=list(spec.cameras) or None, rate_hz=spec.rate_hz,
        max_steps=recipe.max_steps or spec.max_steps, placement=spec.placement,
        tall=spec.tall, reward=asdict(recipe.reward),
    )  # fmt: skip
    return Monitor(LearnerEnv(env, recipe, base), info_keywords=("is_success",))


# --- the recipe and the training ------------------------------------------------------------


def _whole(value, low: int, high: int, where: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise InputError(f"{where} = {value!r:.24}: a whole number from {low} to {high}")
    return value


def _number(value, low: float, high: float, where: str, low_open: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not (ok and (value > low if low_open else value >= low) and value <= high):
        side = f"above {low}" if low_open else f"from {low}"
        raise InputError(f"{where} = {value!r:.24}: a number {side} to {high}")
    return float(value)


def check_recipe(recipe: RlRecipe) -> RlRecipe:
    """Refuse, in one line naming the field, a recipe that cannot train: an unknown
    algorithm, a budget of no steps or one smaller than a rollout, sizes out of range, a
    bad reward. The recipe, its reward checked."""
    w = "training.rl"
    if recipe.algorithm not in ALGORITHMS:
        raise InputError(f"{w}.algorithm {recipe.algorithm!r}; choose one of: "
                         f"{', '.join(ALGORITHMS)}")  # fmt: skip
    _whole(recipe.envs, 1, 64, f"{w}.envs")
    _whole(recipe.rollout, 8, 1_000_000, f"{w}.rollout")
    _whole(recipe.epochs, 1, 100, f"{w}.epochs")
    _whole(recipe.max_steps, 0, 1_000_000, f"{w}.max_steps")
    steps = recipe.steps
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
        raise InputError(f"{w}.steps = {steps!r:.24}: a whole number of environment steps, "
                         "1 or more")  # fmt: skip
    one = recipe.rollout * recipe.envs
    if steps < one:
        raise InputError(
            f"{w}.steps = {steps}: fewer than one rollout ({recipe.rollout} steps x "
            f"{recipe.envs} environments = {one}); give at least {one}, or a shorter rollout"
        )
    _whole(recipe.batch_size, 2, one, f"{w}.batch_size")
    _number(recipe.lr, 0.0, 1.0, f"{w}.lr", low_open=True)
    _number(recipe.gamma, 0.0, 1.0, f"{w}.gamma", low_open=True)
    _number(recipe.residual_scale, 0.0, 1.0, f"{w}.residual_scale", low_open=True)
    _number(recipe.residual_gripper, 0.0, 0.08, f"{w}.residual_gripper")
    _number(recipe.log_std, -10.0, 2.0, f"{w}.log_std")
    dims = recipe.hidden_dims
    widths = isinstance(dims, list) and all(
        isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= 4096 for n in dims
    )
    if not (widths and dims):
        raise InputError(f"{w}.hidden_dims = {dims!r:.40}: a list of layer widths, 1 to 4096")
    return replace(recipe, reward=check_reward(recipe.reward, f"{w}.reward"))


def digest(folder: Path) -> str:
    """The SHA-256 of a checkpoint's weights: what a residual names its base by."""
    h = hashlib.sha256()
    with open(Path(folder) / "model.safetensors", "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class Progress:
    """One row an episode (steps so far, return, length, success), a line every rollout,
    and the figures the folder's ``rl.json`` keeps. A Stable-Baselines3 callback is made
    from it by :func:`_callback`."""

    def __init__(self, log) -> None:
        self.rows: list[dict] = []
        self._log = log
        self.logged = -1  # the steps of the last line printed
        self.t0 = time.perf_counter()

    def log(self, steps: int) -> None:
        """Print the line for ``steps``, once: the callback's at a rollout's end, and the
        training's last unless the callback has just printed it."""
        if steps != self.logged:
            self._log(self.line(steps))
            self.logged = steps

    def episode(self, steps: int, info: dict) -> None:
        ep = info["episode"]
        self.rows.append({
            "steps": steps, "return": float(ep["r"]), "length": int(ep["l"]),
            "success": bool(info.get("is_success", False)),
            "wall_s": round(time.perf_counter() - self.t0, 2),
        })  # fmt: skip

    def line(self, steps: int) -> str:
        recent = self.rows[-50:]
        rate = steps / max(time.perf_counter() - self.t0, 1e-9)
        if not recent:
            return f"{steps} steps, {rate:.0f} steps/s, no episode ended yet"
        won = sum(r["success"] for r in recent)
        mean = float(np.mean([r["return"] for r in recent]))
        return (f"{steps} steps, {rate:.0f} steps/s, {len(self.rows)} episodes; the last "
                f"{len(recent)}: return {mean:.1f}, success {won}/{len(recent)}")  # fmt: skip


def _callback(progress: Progress, every: int):
    from stable_baselines3.common.callbacks import BaseCallback

    class Callback(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals.get("infos", ()):
                if "episode" in info:
                    progress.episode(self.num_timesteps, info)
            now, before = self.num_timesteps, self.num_timesteps - self.training_env.num_envs
            if now // every > before // every:
                progress.log(now)
            return True

    return Callback()


def draw_curve(rows: list[dict], path: Path, title: str, window: int = 50) -> None:
    """Success (over the last ``window`` episodes, drawn from the tenth on) and return
    against environment steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 5.2), dpi=100, sharex=True)
    steps = np.array([r["steps"] for r in rows], float)
    won = np.array([r["success"] for r in rows], float)
    ret = np.array([r["return"] for r in rows], float)
    if len(rows):
        k = np.arange(len(rows))
        start = np.maximum(0, k - window + 1)
        cum_w, cum_r = np.r_[0, np.cumsum(won)], np.r_[0, np.cumsum(ret)]
        n = k - start + 1
        full = n >= min(10, max(1, len(rows) // 2))  # a rate over few episodes says little
        top.plot(steps[full], (100 * (cum_w[k + 1] - cum_w[start]) / n)[full], color="C2")
        bottom.plot(steps, ret, ".", color="C0", alpha=0.25, ms=3)
        bottom.plot(steps[full], ((cum_r[k + 1] - cum_r[start]) / n)[full], color="C0")
    top.set_ylim(-2, 102)
    top.set_ylabel(f"success, last {window} episodes (%)")
    bottom.set_ylabel("episode return")
    bottom.set_xlabel("environment steps")
    top.set_title(title, fontsize=10)
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _model(recipe: RlRecipe, venv, seed: int, residual: bool):
    import torch

    policy_kwargs = {"net_arch": list(recipe.hidden_dims)}
    if recipe.algorithm == "ppo":
        from stable_baselines3 import PPO

        model = PPO(
            "MlpPolicy", venv, learning_rate=recipe.lr, n_steps=recipe.rollout,
            batch_size=recipe.batch_size, n_epochs=recipe.epochs, gamma=recipe.gamma,
            policy_kwargs={**policy_kwargs, "log_std_init": recipe.log_std}, seed=seed,
            device="cpu", verbose=0,
        )  # fmt: skip
        last = model.policy.action_net
    else:
        from stable_baselines3 import SAC

        model = SAC(
            "MlpPolicy", venv, learning_rate=recipe.lr, buffer_size=max(recipe.steps, 1000),
            learning_starts=recipe.rollout, batch_size=recipe.batch_size, gamma=recipe.gamma,
            policy_kwargs={**policy_kwargs, "log_std_init": recipe.log_std}, seed=seed,
            device="cpu", verbose=0,
        )  # fmt: skip
        last = model.policy.actor.mu
    if residual:  # the residual starts as no correction at all (ResiP)
        with torch.no_grad():
            last.weight.zero_()
            last.bias.zero_()
    # A logger of our own, writing nowhere: Stable-Baselines3's default makes an
    # SB3-<date> folder in TMPDIR at every learn(), left there (the progress is ours).
    from stable_baselines3.common.logger import Logger

    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def train_rl(scenario, label: str, out, recipe: RlRecipe, seed: int = 0, log=print) -> dict:
    """Train ``recipe`` on ``scenario``'s episodes into the staged folder ``out``
    (:class:`cake_drake.outputs.files.OutputDir`); what ``rl.json`` says of it."""
    import torch

    from cake_drake.learning.recording import spec_from_scenario
    from cake_drake.scenario import Policy, portable_path, resolve_path

    recipe = check_recipe(recipe)
    if not isinstance(scenario.reference, Policy):
        raise InputError(f"{label}: RL trains a task whose reference is a !Policy (its action "
                         "space, rate and step budget); this one is planned")  # fmt: skip
    spec = spec_from_scenario(scenario)
    if spec.control_mode not in SPACES:
        raise InputError(f"{label}: reference.action_space {spec.control_mode}; RL learns "
                         f"{' or '.join(SPACES)}")  # fmt: skip
    base, base_info = "", None
    if recipe.base:
        from cake_drake.learning.checkpoint import camera_features, check_folder, read_checkpoint

        base_path = resolve_path(recipe.base)
        folder = check_folder(base_path, spec.control_mode, "cpu", spec.cameras)
        if (base_path / FILE).is_file():
            raise InputError(f"training.rl.base {recipe.base}: an RL checkpoint; a residual "
                             "corrects a policy learned by imitation")  # fmt: skip
        base = str(base_path)
        sees = camera_features(read_checkpoint(folder))
        spec = replace(spec, cameras=tuple(c for c in spec.cameras if c.name in sees))
        base_info = {"path": portable_path(base_path), "sha256": digest(folder)}
    else:
        spec = replace(spec, cameras=())
    torch.set_num_threads(1)  # the environments have the other cores
    factory = partial(learner_env, spec, recipe, base)
    if recipe.envs == 1:
        from stable_baselines3.common.vec_env import DummyVecEnv

        venv = DummyVecEnv([factory])
    else:
        from stable_baselines3.common.vec_env import SubprocVecEnv

        venv = SubprocVecEnv([factory] * recipe.envs, start_method="spawn")
    from stable_baselines3.common.vec_env import VecNormalize

    # Returns scaled for the value function's sake while training; what is saved acts on
    # raw observations (they are not normalised), so nothing else is needed to run it.
    venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=recipe.gamma)
    progress = Progress(log)
    kind = "residual" if base else "scratch"
    try:
        model = _model(recipe, venv, seed, bool(base))
        every = max(recipe.rollout * recipe.envs, 1000)
        model.learn(total_timesteps=recipe.steps, callback=_callback(progress, every))
    finally:
        venv.close()
    steps = int(model.num_timesteps)
    minutes = (time.perf_counter() - progress.t0) / 60.0
    progress.log(steps)  # the last line, where the callback did not print it
    model.save(out.path(MODEL))
    with open(out.path(PROGRESS), "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, ["steps", "return", "length", "success", "wall_s"])
        writer.writeheader()
        writer.writerows(progress.rows)
    recent = progress.rows[-50:]
    info = {
        "format": FORMAT,
        "kind": kind,
        "algorithm": recipe.algorithm,
        "action_space": spec.control_mode,
        "observation_size": OBSERVATION_SIZE + (len(model.action_space.low) if base else 0),
        "action_size": int(model.action_space.shape[0]),
        "residual_scale": recipe.residual_scale,
        "residual_gripper": recipe.residual_gripper,
        "base": base_info,
        "task": label,
        "reward": asdict(recipe.reward),
        "recipe": {k: v for k, v in asdict(recipe).items() if k != "reward"},
        "seed": seed,
        "steps": steps,
        "episodes": len(progress.rows),
        "minutes": round(minutes, 2),
        "steps_per_s": round(steps / max(minutes * 60.0, 1e-9), 1),
        "last_episodes_success": [sum(r["success"] for r in recent), len(recent)],
    }
    out.write_json(FILE, info)
    title = f"{label}: {KIND_LABELS[kind]} ({recipe.algorithm.upper()}), {steps} steps, " \
            f"{minutes:.1f} min"  # fmt: skip
    draw_curve(progress.rows, out.path(CURVE), title)
    return info


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
    if info.get("format") != FORMAT:
        raise InputError(f"{path}: field 'format' is {info.get('format')!r}; this version "
                         f"reads {FORMAT}")  # fmt: skip
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
    from cake_drake.scenario import resolve_path

    info = read_rl(path)
    if device not in ("auto", "cpu"):
        raise InputError(f"{path}: an RL policy acts on the CPU; device {device!r} is not for it")
    check_weights(path, info)
    if info["action_space"] != action_space:
        raise InputError(f"{path}: learned in {info['action_space']}; the run's action space "
                         f"is {action_space}")  # fmt: skip
    if info["kind"] == "residual":
        from cake_drake.learning.checkpoint import check_folder as check_base

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
    from cake_drake.learning.checkpoint import _config, camera_features, model_folder
    from cake_drake.scenario import resolve_path

    info = read_rl(path)
    if info["kind"] != "residual":
        return {}
    return camera_features(_config(model_folder(resolve_path(info["base"]["path"]))))


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
        from cake_drake.geometric.ik import Kinematics
        from cake_drake.policy import spaces
        from cake_drake.scenario import resolve_path

        info = self.info
        if info["kind"] == "residual":
            from cake_drake.learning.checkpoint import CheckpointPolicy

            self.base = CheckpointPolicy(str(resolve_path(info["base"]["path"])), "cpu")
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


__all__ = ["RlPolicy", "check_recipe", "read_rl", "train_rl"]
