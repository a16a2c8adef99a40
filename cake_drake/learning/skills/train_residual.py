"""A residual for the last millimetres: RL on one place at a time (``train --rl`` on a task
whose ``motion.skills`` is a skill that never sees the arm).

The environment is ``CakeDrake/Skill-v0`` with the task's problems (``task.generate``:
3 to its number of cubes, ``tall``), placement jitter, cube masses and controller; its
episodes are the places (stack, put-down) the base skill reaches in its own runs. The
learner (Stable-Baselines3's PPO or SAC, the task's ``training.rl`` recipe) reads the
skill's input and the base skill's answer and adds a bounded correction to the base's
hand moves (:mod:`cake_drake.learning.skills.residual`); its last layer starts at
zero, so before training it is the base, number for number.

Every ``eval_every`` steps the learner is measured without exploration on the same
``eval_episodes`` held-out places (seeds no training episode draws): the share whose
effects held within 5 mm and their offsets. Those points are the curve's second panel,
and the best of them (most placed, then the smallest 95th-percentile offset) is the
model the folder keeps.
"""

from __future__ import annotations

import csv
import time
from dataclasses import asdict
from functools import partial
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium import spaces as gs

from cake_drake.errors import InputError
from cake_drake.learning.skills import residual as skill_rl
from cake_drake.learning.skills.env import SkillEnv
from cake_drake.learning.skills.relative import INPUT, RelativeSkill
from cake_drake.learning.training.rl import (
    Progress,
    _callback,
    _model,
    check_recipe,
    close_envs,
    draw_curve,
    vec_env,
)
from cake_drake.scenario import RlRecipe, portable_path, resolve_path
from cake_drake.systems.skills import DEFAULT_BUDGET

#: Held-out evaluation: the first seed (training draws its episodes from the learner's seed).
EVAL_SEED = 900_000


class SkillLearnerEnv(gymnasium.Wrapper):
    """``CakeDrake/Skill-v0`` as the learner sees it: the skill's input and the base's
    answer in, four numbers from -1 to 1 out (the base's moves corrected)."""

    def __init__(self, env: SkillEnv, base: str, scale: float) -> None:
        super().__init__(env)
        self.base = RelativeSkill(base)
        self.scale = scale
        self.action_space = gs.Box(-1.0, 1.0, (skill_rl.ACTION_SIZE,), np.float32)
        self.observation_space = gs.Box(-np.inf, np.inf, (skill_rl.OBSERVATION_SIZE,), np.float32)
        self._base_action = None

    def _answer(self, obs) -> np.ndarray:
        self._base_action = self.base.act({INPUT: obs})
        return skill_rl.learner_input(obs, self._base_action)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.base.reset()
        return self._answer(obs), info

    def step(self, answer):
        action = skill_rl.compose(self._base_action, answer, self.scale)
        obs, reward, terminated, truncated, info = self.env.step(action.astype(np.float32))
        return self._answer(obs), reward, terminated, truncated, info


def skill_env(scenario, recipe: RlRecipe, base: str, starts: bool = True) -> SkillEnv:
    """The task's ``CakeDrake/Skill-v0``: its problems, world, controller and reward, and
    (with ``starts``) the recipe's start pool."""
    world, gen, motion = scenario.world, scenario.task.generate, scenario.motion
    if gen is None:
        raise InputError("a skill residual trains on generated problems: give the task "
                         "task.generate (its number of cubes, tall)")  # fmt: skip
    masses = list(world.cube_mass_range_kg) or ()
    return SkillEnv(
        skill=base, blocks=(min(3, gen.blocks), gen.blocks), tall=gen.tall, actions="places",
        placement=(world.placement.xy, world.placement.yaw_deg), cube_mass_range_kg=masses,
        controller=scenario.controller, reward=asdict(recipe.reward),
        budget=motion.skill_max_steps or DEFAULT_BUDGET, rate_hz=motion.skill_rate_hz,
        time_step=world.time_step, starts=recipe.starts if starts else "",
    )  # fmt: skip


def record_starts(scenario, label: str, path, count: int) -> int:
    """A start pool for the task's residual: ``count`` starts, each where the base skill
    began a place in a run of the task's problems (seeds from the scenario's seed on),
    written to ``path`` whole; the starts written."""
    from cake_drake.learning.skills import starts as start_pool

    recipe = check_recipe(scenario.training.rl)
    base = _base(scenario, recipe, label)
    env = skill_env(scenario, recipe, base, starts=False)
    pool = env.record(count, scenario.seed)
    start_pool.write(path, start_pool.settings_of(env), env.skill_digest, pool)
    return len(pool)


def _base(scenario, recipe: RlRecipe, label: str) -> str:
    """The skill the residual corrects, checked: one that never sees the arm."""
    from cake_drake.learning.skills import checkpoints as skills

    base_path = resolve_path(recipe.base or scenario.motion.skills)
    if not skills._relative(base_path) or skills._with_rl(base_path):
        where = "training.rl.base" if recipe.base else "motion.skills"
        raise InputError(f"{label}: {where} {portable_path(base_path)}: a skill residual "
                         "corrects a skill that never sees the arm (skill.json), and this is "
                         "not one")  # fmt: skip
    skills.check_folder(base_path)
    return str(base_path)


def learner_env(scenario, recipe: RlRecipe, base: str):
    """The learner's environment (a module-level factory: pickled into each process)."""
    from stable_baselines3.common.monitor import Monitor  # SB3 imports torch: seconds

    env = SkillLearnerEnv(skill_env(scenario, recipe, base), base, recipe.residual_scale)
    return Monitor(env, info_keywords=("is_success",))


def measure(model, env: SkillLearnerEnv, episodes: int) -> dict:
    """The learner without exploration on ``episodes`` held-out places: placed within 5 mm,
    and the offsets (mm) of the places whose effects held."""
    won, offsets = 0, []
    for k in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED + k)
        while True:
            answer, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(answer)
            if terminated or truncated:
                break
        won += bool(info["is_success"])
        if info["reward_terms"]["goal"] == 1.0:
            offsets.append(info["offset_mm"])
    p95 = float(np.percentile(offsets, 95)) if offsets else float("inf")
    return {"placed": won, "of": episodes, "median_mm": float(np.median(offsets)) if offsets
            else float("inf"), "p95_mm": p95}  # fmt: skip


def train_skill_rl(
    scenario, label: str, out, recipe: RlRecipe, seed: int = 0, log=print, cluster=None
) -> dict:
    """Train the residual on the task's places into the staged folder ``out``; what
    ``skill_rl.json`` says of it."""
    import torch  # torch and Stable-Baselines3 below: seconds, only where one trains

    recipe = check_recipe(recipe)
    base = _base(scenario, recipe, label)
    base_path = Path(base)
    if recipe.starts:  # the pool checked here, before the runners start
        skill_env(scenario, recipe, base).close()
    torch.set_num_threads(1)
    factory = partial(learner_env, scenario, recipe, base)
    venv = vec_env(factory, recipe, cluster)
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList, EveryNTimesteps

    progress = Progress(log)
    eval_every, eval_episodes = recipe.eval_every, recipe.eval_episodes
    checks: list[dict] = []
    best = {"key": None, "steps": 0}
    held_out = skill_env(scenario, recipe, base, starts=False)  # replayed: seeds of its own
    evaluator = SkillLearnerEnv(held_out, base, recipe.residual_scale)

    def check_now(model, steps: int) -> None:
        found = measure(model, evaluator, eval_episodes)
        found["steps"] = steps
        found["minutes"] = round((time.perf_counter() - progress.t0) / 60.0, 2)
        checks.append(found)
        log(f"{steps} steps: without exploration, {found['placed']}/{found['of']} held-out "
            f"places within 5 mm, offsets {found['median_mm']:.2f} mm median, "
            f"{found['p95_mm']:.2f} mm p95")  # fmt: skip
        key = (found["placed"], -found["p95_mm"])
        if best["key"] is None or key > best["key"]:
            best.update(key=key, steps=steps)
            model.save(out.path(skill_rl.MODEL))

    class Check(BaseCallback):
        def _on_step(self) -> bool:
            check_now(self.model, self.num_timesteps)
            return True

    finished = False
    try:
        model = _model(recipe, venv, seed, residual=True)
        if eval_every:
            check_now(model, 0)  # the base alone: the residual starts at zero
        every = max(recipe.rollout * recipe.envs, 1000)
        callbacks = [_callback(progress, every, recipe.minutes)]
        if eval_every:
            callbacks.append(EveryNTimesteps(eval_every, Check()))
        model.learn(total_timesteps=recipe.steps, callback=CallbackList(callbacks))
        finished = True
    finally:
        close_envs(venv, finished)
        evaluator.close()
    steps = int(model.num_timesteps)
    if eval_every and checks[-1]["steps"] != steps:
        check_now(model, steps)
    if not eval_every:
        model.save(out.path(skill_rl.MODEL))
    minutes = (time.perf_counter() - progress.t0) / 60.0
    progress.log(steps)
    with open(out.path(skill_rl.PROGRESS), "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, ["steps", "return", "length", "success", "wall_s"])
        writer.writeheader()
        writer.writerows(progress.rows)
    recent = progress.rows[-50:]
    info = {
        "format": skill_rl.FORMAT,
        "kind": skill_rl.KIND,
        "algorithm": recipe.algorithm,
        "action_space": "ee_delta",
        "observation_size": skill_rl.OBSERVATION_SIZE,
        "action_size": skill_rl.ACTION_SIZE,
        "residual_scale": recipe.residual_scale,
        "base": {"path": portable_path(base_path), "sha256": skill_rl.digest(base_path)},
        "task": label,
        "episodes_of": "the places (stack, put-down) of the task's problems, "
        + (f"from the start pool {recipe.starts}" if recipe.starts else "reached by the base"),
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
        "checks": checks,
        "kept": f"the model of step {best['steps']}" if eval_every else "the last model",
    }
    out.write_json(skill_rl.FILE, info)
    title = f"{label}: skill + RL residual ({recipe.algorithm.upper()}), {steps} steps, " \
            f"{minutes:.1f} min"  # fmt: skip
    points = [(c["steps"], 100.0 * c["placed"] / c["of"]) for c in checks]
    draw_curve(progress.rows, out.path(skill_rl.CURVE), title, checks=points)
    return info
