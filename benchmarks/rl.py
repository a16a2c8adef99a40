"""Reinforcement learning on these cores: the environment's throughput, and what RL trained.

``--throughput`` steps ``CakeDrake/Stack-v0`` on stack2 (the residual's task, joint
positions held from the measured joints) and prints steps per second: from the state in
one process and in Gymnasium's ``make_vec`` with two processes (spawned: a forked
renderer hangs), then with the task's two
96 x 96 cameras rendering every step, the same two ways; and with the pixel policy
answering every step in one process (what a residual's training steps through); then
``CakeDrake/Skill-v0``, the shipped relative skill answering, one process and two.

``--runners`` trains PPO from scratch on stack2's state (the task's recipe, ``--steps``
environment steps a row) with its environments in this process, in two spawned
processes, and as one and two Ray actors on a local instance, and prints each
training's steps per second, learner included: what ``train --rl --ray`` costs and buys.

``--compare DIR...`` evaluates the base policy each RL folder corrects (once), and each
folder, on the same held-out episodes (``--episodes``, from ``--seed``), through
``python -m cake_drake.evaluate``'s library, and prints one row each: success with its
95 % interval, the environment steps and minutes the training took. ``--figure PNG`` draws
every folder's success (over its last 50 training episodes) against environment steps in
one figure, with the held-out success of each base alone.

    python benchmarks/rl.py --throughput
    python benchmarks/rl.py --runners --steps 2048
    python benchmarks/rl.py --compare outputs/rl/stack2_pixels_rl outputs/rl/stack2_scratch \
        --episodes 50 --figure docs/images/rl_curves.png
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from machine import machine

ROOT = Path(__file__).resolve().parents[1]

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
PIXELS = ROOT / "models" / "policies" / "stack2_pixels"
SKILL_ID = "cake_drake.gym:CakeDrake/Skill-v0"


def _spec(cameras: bool):
    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.scenario import load_scenario

    spec = spec_from_scenario(load_scenario(LEARNING, "stack2"))
    return spec if cameras else replace(spec, cameras=())


def _make(cameras: bool):
    return _spec(cameras).env()


def _hold(obs) -> np.ndarray:
    state = obs["state"]
    return np.asarray(state[..., :8], np.float32)


def throughput(steps: int) -> None:
    import gymnasium

    print(f"CakeDrake/Stack-v0 on stack2, joint positions, {steps} steps a row (episodes of "
          "400 steps at most, reset when they end)")  # fmt: skip
    for cameras in (False, True):
        what = "two 96 x 96 cameras" if cameras else "state"
        env = _make(cameras)
        obs, _ = env.reset(seed=1)
        t0 = time.perf_counter()
        for k in range(steps):
            obs, _, term, trunc, _ = env.step(_hold(obs))
            if term or trunc:
                obs, _ = env.reset(seed=2 + k)
        rate = steps / (time.perf_counter() - t0)
        print(f"  {what:<22} one process      {rate:7.0f} steps/s")
        spec = _spec(cameras)
        venv = gymnasium.make_vec(
            "cake_drake.gym:CakeDrake/Stack-v0", num_envs=2, vectorization_mode="async",
            problem=spec.problem, control_mode=spec.control_mode, placement=spec.placement,
            max_steps=spec.max_steps, obs_mode="state+rgb" if cameras else "state",
            cameras=list(spec.cameras) or None, vector_kwargs={"context": "spawn"},
        )  # fmt: skip
        obs, _ = venv.reset(seed=1)
        venv.step(_hold(obs))  # the processes warm
        t0 = time.perf_counter()
        for _ in range(steps // 2):
            obs, *_ = venv.step(_hold(obs))
        rate = 2 * (steps // 2) / (time.perf_counter() - t0)
        venv.close()
        print(f"  {what:<22} make_vec x 2     {rate:7.0f} steps/s")
    from cake_drake.learning.policies.lerobot_checkpoint import CheckpointPolicy

    env = _make(True)
    obs, _ = env.reset(seed=1)
    base = CheckpointPolicy(str(PIXELS), "cpu")
    base.reset(env.unwrapped.policy_task, 1)
    t0 = time.perf_counter()
    for k in range(steps):
        obs, _, term, trunc, _ = env.step(base.act(obs))
        if term or trunc:
            obs, _ = env.reset(seed=2 + k)
            base.reset(env.unwrapped.policy_task, 2 + k)
    rate = steps / (time.perf_counter() - t0)
    print(f"  {'cameras + stack2_pixels':<22} one process      {rate:7.0f} steps/s")
    skill_throughput(steps)


def _skill_env(pool: str = ""):
    import gymnasium

    from cake_drake.learning.skills.env import SkillEnv

    return SkillEnv(starts=pool) if pool else gymnasium.make(SKILL_ID).unwrapped


class _Answered:
    """One Skill-v0 with the relative skill answering it: the steps of a row."""

    def __init__(self, env) -> None:
        from cake_drake.learning.skills.relative import RelativeSkill

        self.env, self.skill = env, RelativeSkill(env.skill_path)

    def answer(self, obs):
        return self.skill.act({"observation.relative": obs})

    def ended(self) -> None:
        self.skill.reset()


def skill_throughput(steps: int, pool_size: int = 40) -> None:
    """CakeDrake/Skill-v0 (the shipped relative skill's places on 3 to 8 cubes), each step
    answered by the skill itself, resets counted in the time: every start replayed (one
    process), then from a start pool of ``pool_size`` starts (recorded first, its time
    printed) in one process, in make_vec with two processes and on two Ray actors."""
    import tempfile

    import gymnasium

    from cake_drake.learning.skills import starts

    print(f"CakeDrake/Skill-v0, places of 3 to 8 cubes, the skill's own answers, {steps} steps "
          "a row (resets included)")  # fmt: skip
    env = _skill_env()
    t0 = time.perf_counter()
    pool = env.record(pool_size, seed=1000)
    took = time.perf_counter() - t0
    problems = len({(s.seed, s.blocks) for s in pool})
    folder = tempfile.mkdtemp()
    path = str(Path(folder) / "starts.json")
    starts.write(path, starts.settings_of(env), env.skill_digest, pool)
    print(f"  a pool of {pool_size} starts of {problems} problems recorded in {took:.1f} s")
    for label, made in (("replayed starts", env), ("start pool", _skill_env(path))):
        one = _Answered(made)
        obs, _ = made.reset(seed=1)
        t0, episodes = time.perf_counter(), 0
        for k in range(steps):
            obs, _, term, trunc, _ = made.step(one.answer(obs))
            if term or trunc:
                obs, _ = made.reset(seed=2 + k)
                one.ended()
                episodes += 1
        rate = steps / (time.perf_counter() - t0)
        print(f"  {label:<22} one process      {rate:7.0f} steps/s ({episodes} episodes)")
    venv = gymnasium.make_vec(SKILL_ID, num_envs=2, vectorization_mode="async",
                              vector_kwargs={"context": "spawn"}, starts=path)  # fmt: skip
    print(f"  {'start pool':<22} make_vec x 2     {_vector_rate(venv, steps):7.0f} steps/s")
    venv.close()
    from functools import partial

    from cake_drake.learning.envs.ray_runners import ray_vec_env
    from cake_drake.sweeps import RayCluster

    cluster = RayCluster(num_cpus=2)
    cluster.start()
    try:
        venv = ray_vec_env(partial(_skill_env, path), 2, cluster)
        print(f"  {'start pool':<22} Ray actors x 2   {_vector_rate(venv, steps, sb3=True):7.0f} "
              "steps/s")  # fmt: skip
        venv.close()
    finally:
        cluster.stop()


def _vector_rate(venv, steps: int, sb3: bool = False) -> float:
    """Steps a second of two environments stepped together, the relative skill answering."""
    from cake_drake.learning.skills.env import DEFAULT_SKILL
    from cake_drake.learning.skills.relative import RelativeSkill

    skills = [RelativeSkill(DEFAULT_SKILL) for _ in range(2)]
    obs = venv.reset() if sb3 else venv.reset(seed=1)[0]
    t0 = time.perf_counter()
    for _ in range(steps // 2):
        pairs = zip(skills, obs, strict=True)
        action = np.stack([s.act({"observation.relative": o}) for s, o in pairs])
        if sb3:
            obs, _, ended, _ = venv.step(action)
        else:
            obs, _, term, trunc, _ = venv.step(action)
            ended = term | trunc
        for k in np.flatnonzero(ended):
            skills[k].reset()
    return 2 * (steps // 2) / (time.perf_counter() - t0)


def runners(steps: int) -> None:
    import tempfile

    from cake_drake.learning.training.rl import FILES, check_recipe, train_rl
    from cake_drake.outputs.files import OutputDir
    from cake_drake.scenario import load_scenario
    from cake_drake.sweeps import RayCluster

    scenario = load_scenario(LEARNING, "stack2")
    base = replace(scenario.training.rl, base="", steps=steps, rollout=256, batch_size=64)
    print(f"PPO from scratch on stack2's state, {steps} environment steps a row, the learner "
          "in this process (steps/s over the whole training)")  # fmt: skip
    rows = [("this process", 1, None), ("spawned processes", 2, None),
            ("Ray actors (local)", 1, "ray"), ("Ray actors (local)", 2, "ray")]  # fmt: skip
    for what, envs, ray in rows:
        recipe = check_recipe(replace(base, envs=envs))
        cluster = RayCluster(num_cpus=envs) if ray else None
        with tempfile.TemporaryDirectory() as tmp:
            with OutputDir(Path(tmp) / "o", "benchmark", FILES) as out:
                info = train_rl(scenario, "stack2", out, recipe, log=lambda line: None,
                                cluster=cluster)  # fmt: skip
        print(f"  {what:<20} x {envs}  {info['steps_per_s']:7.1f} steps/s")


def _evaluate(path: Path, seeds: list[int], workers: int) -> dict:
    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.learning.evaluation import evaluate
    from cake_drake.scenario import CHECKPOINT_POLICY, load_scenario

    scenario = load_scenario(LEARNING, "stack2")
    spec = spec_from_scenario(scenario)
    from cake_drake.learning.policies.checkpoint import check_folder, sees

    check_folder(path, spec.control_mode, "cpu", scenario.cameras)
    cameras = tuple(c for c in spec.cameras if c.name in sees(path))
    options = {"path": str(path.resolve()), "device": "cpu"}
    spec = replace(spec, policy=CHECKPOINT_POLICY, options=options, cameras=cameras)
    t0 = time.perf_counter()
    rows, summary = evaluate(spec, seeds, workers)
    summary["minutes"] = (time.perf_counter() - t0) / 60
    summary["won"] = [r["seed"] for r in rows if r["success"]]
    return summary


def _row(label: str, summary: dict, trained: str = "") -> str:
    lo, hi = summary["ci95"]
    return (f"  {label:<34} {summary['success']:>3}/{summary['episodes']:<3} "
            f"({100 * lo:3.0f}-{100 * hi:3.0f} %)  {summary['mean_steps']:6.0f} steps  "
            f"{trained}")  # fmt: skip


def compare(folders: list[Path], seeds: list[int], workers: int) -> dict[str, float]:
    """Each folder's row (and its base's, once); the bases' success rates by name."""
    from cake_drake.learning.policies.rl import KIND_LABELS, read_rl
    from cake_drake.scenario import resolve_path

    print(f"stack2, held-out seeds {seeds[0]}..{seeds[-1]}: success (95 % interval), mean "
          "steps an episode; the training's environment steps and minutes")  # fmt: skip
    bases: dict[str, dict] = {}
    for folder in folders:
        info = read_rl(folder)
        if info["kind"] == "residual" and info["base"]["path"] not in bases:
            base = resolve_path(info["base"]["path"])
            bases[info["base"]["path"]] = got = _evaluate(base, seeds, workers)
            print(_row(f"{base.name} (base, imitation)", got), flush=True)
        trained = f"{info['steps']} env steps, {info['minutes']:.0f} min"
        label = f"{folder.name} ({KIND_LABELS[info['kind']]})"
        got = _evaluate(folder, seeds, workers)
        print(_row(label, got, trained), flush=True)
        if info["kind"] == "residual":
            before = set(bases[info["base"]["path"]]["won"])
            print(f"    built only with the residual: {sorted(set(got['won']) - before)}; "
                  f"only without: {sorted(before - set(got['won']))}")  # fmt: skip
    return {resolve_path(k).name: v["rate"] for k, v in bases.items()}


def figure(folders: list[Path], path: Path, bases: dict[str, float], window: int = 50) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cake_drake.learning.policies.rl import KIND_LABELS, PROGRESS, read_rl

    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=100)
    for k, folder in enumerate(folders):
        info = read_rl(folder)
        with open(folder / PROGRESS, encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        steps = np.array([int(r["steps"]) for r in rows])
        won = np.array([r["success"] == "True" for r in rows], float)
        cum = np.r_[0.0, np.cumsum(won)]
        i = np.arange(len(rows))
        start = np.maximum(0, i - window + 1)
        n = i - start + 1
        rate = np.where(n >= 10, 100 * (cum[i + 1] - cum[start]) / n, np.nan)
        label = f"{KIND_LABELS[info['kind']]} ({info['algorithm'].upper()}, "
        label += f"{info['minutes']:.0f} min)"
        ax.plot(steps, rate, color=f"C{k}", label=label)
    for name, rate in bases.items():
        ax.axhline(100 * rate, color="0.4", ls="--", lw=1)
        where = ("axes fraction", "data")
        ax.annotate(f"{name} alone, held out", (0.99, 100 * rate + 1.5), xycoords=where,
                    ha="right", fontsize=8, color="0.3")  # fmt: skip
    ax.set_xlabel("environment steps (2 environments side by side)")
    ax.set_ylabel(f"success, last {window} training episodes (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=9)
    ax.set_title("stack2: PPO from scratch (state), and a residual on the pixel policy",
                 fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    print(f"figure: {path}")


def residual_curves(folders: list[Path], path: Path) -> None:
    """Each skill residual's held-out checks: the places' 95th-percentile offset against
    environment steps and against minutes of training, beside its base's (the check at 0)."""
    import json

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_steps, by_time) = plt.subplots(1, 2, figsize=(9.0, 3.8), dpi=100, sharey=True)
    for folder in folders:
        info = json.loads((folder / "skill_rl.json").read_text())
        checks = info["checks"]
        with open(folder / "progress.csv", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
        at = np.array([int(r["steps"]) for r in rows]), np.array([float(r["wall_s"]) for r in rows])
        steps = np.array([c["steps"] for c in checks])
        minutes = np.array([c.get("minutes", np.interp(c["steps"], *at) / 60.0) for c in checks])
        p95 = np.array([c["p95_mm"] for c in checks])
        label = f"{folder.name} ({info['algorithm'].upper()})"
        by_steps.plot(steps, p95, "o-", label=label)
        by_time.plot(minutes, p95, "o-", label=label)
        for c, x, y in zip(checks, steps, p95, strict=True):  # a check that lost places
            if c["placed"] < c["of"]:
                by_steps.annotate(f"{c['placed']}/{c['of']} placed", (x, y), fontsize=7,
                                  xytext=(4, -10), textcoords="offset points")  # fmt: skip
    for ax, what in ((by_steps, "environment steps"), (by_time, "minutes of training")):
        ax.set_xlabel(what)
        ax.grid(alpha=0.3)
    by_steps.set_ylabel("held-out places, 95th percentile offset (mm)")
    by_steps.legend(fontsize=8)
    fig.suptitle("Skill residuals: held-out places within 5 mm during training (the first "
                 "point: the base)")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path)
    print(f"{path}: {len(folders)} residuals' checks")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--throughput", action="store_true")
    p.add_argument("--skill-throughput", action="store_true",
                   help="CakeDrake/Skill-v0's rows of --throughput alone")  # fmt: skip
    p.add_argument("--steps", type=int, default=400, help="--throughput/--runners: steps a row")
    p.add_argument("--runners", action="store_true")
    p.add_argument("--compare", type=Path, nargs="+", metavar="DIR", default=[])
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--seed", type=int, default=100_000, help="the first held-out seed")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--figure", type=Path, help="--compare: the success curves to this PNG")
    p.add_argument("--residual-curves", type=Path, nargs="+", metavar="DIR", default=[],
                   help="skill residuals' held-out checks, drawn to --figure")  # fmt: skip
    args = p.parse_args()
    print(machine())
    if args.throughput:
        throughput(args.steps)
    elif args.skill_throughput:
        skill_throughput(args.steps)
    if args.runners:
        runners(args.steps)
    if args.compare:
        seeds = list(range(args.seed, args.seed + args.episodes))
        bases = compare(args.compare, seeds, args.workers)
        if args.figure:
            figure(args.compare, args.figure, bases)
    elif args.residual_curves:
        residual_curves(args.residual_curves, args.figure or Path("residual_curves.png"))


if __name__ == "__main__":
    main()
