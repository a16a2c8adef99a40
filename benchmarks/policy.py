"""Policy-slot benchmark: environment steps per second, the cost of a frame, and the
expert's success rate over seeded generated problems.

(a) speed: ``CakeDrake/Stack-v0`` stepped with random actions in each control mode, in
    ``state`` and in ``state+rgb`` (two 224 x 224 cameras), 10 Hz control, 10 ms
    simulation steps; steps per second of wall clock in this one process (one core), and
    the cost of one rendered frame.
(b) success: the expert (``examples/expert_policy.py``) through the environment on
    ``--seeds`` generated problems of 3 to 8 blocks in ``ee_delta`` (the goal is 95 %),
    and the random policy on the same problems (the measure must be able to fail).

    python benchmarks/policy.py [--seeds 30] [--steps 200]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gymnasium  # noqa: E402
from machine import machine  # noqa: E402 - benchmarks/machine.py

from cake_drake.learning.evaluation import wilson  # noqa: E402
from cake_drake.world.cameras import renderer_line  # noqa: E402

ENV_ID = "cake_drake.gym:CakeDrake/Stack-v0"
CHUNK = {"horizon": 10, "execute": 5}


def speed(mode: str, obs_mode: str, steps: int) -> tuple[float, float]:
    options = CHUNK if mode == "joint_chunk" else {}
    env = gymnasium.make(ENV_ID, blocks=5, control_mode=mode, obs_mode=obs_mode, options=options)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    periods = CHUNK["execute"] if mode == "joint_chunk" else 1
    t0 = time.perf_counter()
    for k, a in enumerate(actions):
        if mode in ("joint_position", "joint_chunk"):  # stay near home: a wild target is slow
            a = np.asarray(a) * 0.0 + _home(env, mode)
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset(seed=k)
    wall = time.perf_counter() - t0
    return steps / wall, steps * periods / wall


def _home(env, mode):
    from cake_drake.world.scene import Q_HOME

    row = np.r_[Q_HOME, 0.08]
    return np.tile(row, (CHUNK["horizon"], 1)) if mode == "joint_chunk" else row


def frame_cost(n: int = 50) -> float:
    env = gymnasium.make(ENV_ID, blocks=5, obs_mode="state+rgb")
    env.reset(seed=0)
    source = env.unwrapped._source
    context = source.GetMyContextFromRoot(env.unwrapped._simulator.get_context())
    sensor = next(iter(env.unwrapped._cake.cameras.values()))
    sensor_context = sensor.GetMyContextFromRoot(env.unwrapped._simulator.get_context())
    t0 = time.perf_counter()
    for _ in range(n):
        sensor_context = sensor.GetMyContextFromRoot(env.unwrapped._simulator.get_context())
        env.unwrapped._simulator.get_mutable_context().SetTime(context.get_time() + 1e-3)
        sensor.color_image_output_port().Eval(sensor_context)
    return (time.perf_counter() - t0) / n * 1000


def success(
    policy: str, seeds: int, mode: str = "ee_delta", max_steps: int = 2000
) -> tuple[list[bool], list[int]]:
    import importlib

    make = importlib.import_module(f"examples.{policy}").make
    won, steps = [], []
    for seed in range(seeds):
        env = gymnasium.make(ENV_ID, blocks=(3, 8), control_mode=mode, max_steps=max_steps)
        obs, info = env.reset(seed=seed)
        p = make()
        p.reset(env.unwrapped.policy_task, seed)
        done = False
        k = 0
        while not done:
            a = p.act(obs)
            if isinstance(a, tuple):
                break
            obs, _, terminated, truncated, info = env.step(a)
            done = terminated or truncated
            k += 1
        won.append(bool(info["is_success"]))
        steps.append(k)
    return won, steps


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=30, help="generated problems for (b)")
    p.add_argument("--steps", type=int, default=200, help="environment steps per row of (a)")
    args = p.parse_args()
    print(machine())
    print(renderer_line())  # the GL implementation the cameras render with: a GPU or llvmpipe
    print(f"(a) environment steps per second, 10 Hz control, 10 ms steps, {args.steps} steps")
    print(f"{'control mode':<16}{'obs mode':<12}{'env steps/s':>12}{'control periods/s':>19}")
    for mode in ("ee_delta", "joint_position", "joint_chunk"):
        for obs_mode in ("state", "state+rgb"):
            per_s, periods = speed(mode, obs_mode, args.steps)
            print(f"{mode:<16}{obs_mode:<12}{per_s:>12.1f}{periods:>19.1f}")
    print(f"one 224 x 224 frame: {frame_cost():.1f} ms")
    print(f"(b) success over {args.seeds} generated problems of 3 to 8 blocks, ee_delta")
    for policy in ("expert_policy", "random_policy"):
        won, steps = success(policy, args.seeds, max_steps=2000 if "expert" in policy else 300)
        lo, hi = wilson(sum(won), len(won))
        print(
            f"{policy:<16} {sum(won)}/{len(won)} = {np.mean(won):.0%} "
            f"(95 % interval {lo:.0%} to {hi:.0%}), median {int(np.median(steps))} steps"
        )


if __name__ == "__main__":
    main()
