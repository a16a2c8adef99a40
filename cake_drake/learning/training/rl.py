"""Learning from a reward (``python -m cake_drake.train --rl SUITE --name TASK --out DIR``).

Stable-Baselines3's PPO (or SAC) trains on ``CakeDrake/Stack-v0`` with the task's
episodes (problem, placement, cameras, step budget), its observation and action spaces
untouched underneath, on the CPU, through Gymnasium's vectorised environments. The
recipe is the task's ``training.rl`` (:class:`cake_drake.scenario.RlRecipe`), the reward
its ``reward`` (:mod:`cake_drake.learning.envs.rewards`). What the learner reads and
what its answer means (:class:`LearnerEnv`), a residual over a frozen base or a policy
from scratch, is :mod:`cake_drake.learning.policies.rl`'s.

The folder ``DIR`` gets ``model.zip`` (Stable-Baselines3's), ``rl.json`` (what it is:
algorithm, action space, the bound, the base and its weights' digest, the reward, the
training's figures), ``progress.csv`` (one row an episode) and ``curve.png`` (success and
return against environment steps); :mod:`cake_drake.learning.policies.rl` reads it back
and runs it wherever a checkpoint runs.
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, replace
from functools import partial
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium import spaces as gs

from cake_drake.errors import InputError
from cake_drake.learning.data.recording import spec_from_scenario
from cake_drake.learning.envs.env import StackEnv
from cake_drake.learning.envs.rewards import check_reward
from cake_drake.learning.policies.lerobot_checkpoint import (
    CheckpointPolicy,
    camera_features,
    check_folder,
    read_checkpoint,
)
from cake_drake.learning.policies.rl import (
    ALGORITHMS,
    CURVE,
    FILE,
    FILES,
    FORMAT,
    KIND_LABELS,
    MODEL,
    OBSERVATION_SIZE,
    PROGRESS,
    SPACES,
    Composer,
    digest,
    observation_vector,
)
from cake_drake.scenario import Policy, RlRecipe, portable_path, resolve_path

# --- the learner's environment -------------------------------------------------------------


class LearnerEnv(gymnasium.Wrapper):
    """``CakeDrake/Stack-v0`` as the learner sees it: one vector in, an answer from -1 to 1
    out, composed with the base's action (:mod:`cake_drake.learning.policies.rl`)."""

    def __init__(self, env, recipe: RlRecipe, base: str = "") -> None:
        super().__init__(env)
        inner = env.unwrapped
        self.base = None
        if base:
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
    from stable_baselines3.common.monitor import Monitor  # SB3 imports torch: seconds

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


#: The largest budget a recipe may ask for (years of simulated steps on these machines),
#: and the largest replay buffer SAC keeps (Stable-Baselines3's default): it is sized by
#: the budget below that.
MAX_STEPS = 100_000_000
REPLAY_MAX = 1_000_000


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
    _whole(recipe.eval_every, 0, 100_000_000, f"{w}.eval_every")
    _whole(recipe.eval_episodes, 1, 10_000, f"{w}.eval_episodes")
    steps = recipe.steps
    if not isinstance(steps, int) or isinstance(steps, bool) or not 1 <= steps <= MAX_STEPS:
        raise InputError(f"{w}.steps = {steps!r:.24}: a whole number of environment steps, "
                         f"1 to {MAX_STEPS:,}")  # fmt: skip
    one = recipe.rollout * recipe.envs
    if steps < one:
        raise InputError(
            f"{w}.steps = {steps}: fewer than one rollout ({recipe.rollout} steps x "
            f"{recipe.envs} environments = {one}); give at least {one}, or a shorter rollout"
        )
    _whole(recipe.batch_size, 2, one, f"{w}.batch_size")
    _number(recipe.minutes, 0.0, 10_000.0, f"{w}.minutes")
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


def _callback(progress: Progress, every: int, minutes: float = 0.0):
    """The callback that keeps ``progress`` and, past ``minutes`` (0: never), stops."""
    from stable_baselines3.common.callbacks import BaseCallback  # SB3 imports torch: seconds

    class Callback(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals.get("infos", ()):
                if "episode" in info:
                    progress.episode(self.num_timesteps, info)
            now, before = self.num_timesteps, self.num_timesteps - self.training_env.num_envs
            if now // every > before // every:
                progress.log(now)
            return not minutes or time.perf_counter() - progress.t0 < 60.0 * minutes

    return Callback()


def draw_curve(
    rows: list[dict], path: Path, title: str, window: int = 50, checks: list | None = None
) -> None:
    """Success (over the last ``window`` episodes, drawn from the tenth on) and return
    against environment steps; ``checks``, (steps, success %) measured without
    exploration, as points on the success panel."""
    import matplotlib  # its pyplot: a second's import, only for the figure

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
    if checks:
        x, y = zip(*checks, strict=True)
        top.plot(x, y, "o-", color="C3", ms=4, label="held-out, no exploration")
        top.plot([], [], color="C2", label=f"training episodes (last {window})")
        top.legend(fontsize=8, loc="lower right")
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


def vec_env(factory, recipe: RlRecipe, cluster=None):
    """The recipe's ``envs`` environments made by ``factory``: Ray actors on ``cluster``,
    in this process (one), or in spawned processes; returns scaled for the value
    function's sake while training (what is saved acts on raw observations, which are
    not normalised, so nothing else is needed to run it)."""
    if cluster is not None:
        from cake_drake.learning.envs.ray_runners import ray_vec_env

        venv = ray_vec_env(factory, recipe.envs, cluster)
    elif recipe.envs == 1:
        from stable_baselines3.common.vec_env import DummyVecEnv

        venv = DummyVecEnv([factory])
    else:
        from stable_baselines3.common.vec_env import SubprocVecEnv

        venv = SubprocVecEnv([factory] * recipe.envs, start_method="spawn")
    from stable_baselines3.common.vec_env import VecNormalize

    return VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=recipe.gamma)


def close_envs(venv, finished: bool) -> None:
    """Close a training's vectorised environments. After an error or an interrupt
    (``finished`` false) the worker processes are stopped, not asked: an interrupt that
    lands between two workers' answers to a step leaves Stable-Baselines3's ``close()``
    waiting for an answer that never comes."""
    inner = venv.unwrapped
    processes = getattr(inner, "processes", None)
    if finished or not processes:
        venv.close()
        return
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=10)
    inner.closed = True


def _model(recipe: RlRecipe, venv, seed: int, residual: bool):
    import torch  # torch and Stable-Baselines3 below: seconds, only where a model is made

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

        replay = min(max(recipe.steps, 1000), REPLAY_MAX)
        model = SAC(
            "MlpPolicy", venv, learning_rate=recipe.lr, buffer_size=replay,
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


def train_rl(
    scenario, label: str, out, recipe: RlRecipe, seed: int = 0, log=print, cluster=None
) -> dict:
    """Train ``recipe`` on ``scenario``'s episodes into the staged folder ``out``
    (:class:`cake_drake.outputs.files.OutputDir`); what ``rl.json`` says of it. With
    ``cluster`` (a :class:`cake_drake.sweeps.RayCluster`) the recipe's environments run
    as Ray actors there, the learner here."""
    import torch  # torch and Stable-Baselines3 below: seconds, only where one trains

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
    venv = vec_env(factory, recipe, cluster)
    progress = Progress(log)
    kind = "residual" if base else "scratch"
    finished = False
    try:
        model = _model(recipe, venv, seed, bool(base))
        every = max(recipe.rollout * recipe.envs, 1000)
        callback = _callback(progress, every, recipe.minutes)
        model.learn(total_timesteps=recipe.steps, callback=callback)
        finished = True
    finally:
        close_envs(venv, finished)
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
        "runners": f"{recipe.envs} on {cluster}"
        if cluster is not None
        else f"{recipe.envs} on this machine",
        "last_episodes_success": [sum(r["success"] for r in recent), len(recent)],
    }
    out.write_json(FILE, info)
    title = f"{label}: {KIND_LABELS[kind]} ({recipe.algorithm.upper()}), {steps} steps, " \
            f"{minutes:.1f} min"  # fmt: skip
    draw_curve(progress.rows, out.path(CURVE), title)
    return info


__all__ = ["FILES", "KIND_LABELS", "LearnerEnv", "check_recipe", "learner_env", "train_rl"]
