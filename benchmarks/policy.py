"""Policy-slot benchmark: environment steps per second, the cost of a frame, and the
expert's success rate over seeded generated problems.

(a) speed: ``CakeDrake/Stack-v0`` stepped with random actions in each control mode, in
    ``state`` and in ``state+rgb`` (two 224 x 224 cameras), 10 Hz control, 10 ms
    simulation steps; steps per second of wall clock in this one process (one core), and
    the cost of one rendered frame.
(b) success: the expert (``examples/expert_policy.py``) through the environment on
    ``--seeds`` generated problems of 3 to 8 blocks in ``ee_delta`` (the goal is 95 %),
    and the random policy on the same problems (the measure must be able to fail).
(c) the step's own cost, as ratios in one run: the ``state`` step against ``AdvanceTo``
    over the same period of the same Diagram with the action held and the slot's update
    doing nothing (no per-step Python of ours); the ``state+rgb`` step against the
    ``state`` step plus one frame per camera (goals: 1.15 and 1.15).
(d) ``--vector N``: ``gymnasium.make_vec(..., vectorization_mode="async")`` with 1, 2,
    4 ... N environments, one process each: aggregate steps per second and the scaling
    efficiency (steps/s of N environments / (N x one environment's)).

    python benchmarks/policy.py [--seeds 30] [--steps 200] [--vector N] [--only c,d]
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium
import numpy as np
from machine import machine  # benchmarks/machine.py

from cake_drake.learning.evaluation import wilson
from cake_drake.world.cameras import renderer_line

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


def _held(env, mode):
    """An action that holds the arm where it is (a joint target at the measured joints)."""
    if mode == "ee_delta":
        return np.r_[np.zeros(6), 1.0]
    return _home(env, mode)


def overhead(mode: str, steps: int, cameras: int = 2) -> dict[str, float]:
    """(c): ms per ``state`` step, per bare ``AdvanceTo``, per ``state+rgb`` step and per
    frame, measured in turn on the same kind of episode."""
    out = {}
    for obs_mode in ("state", "state+rgb"):
        env = gymnasium.make(ENV_ID, blocks=5, control_mode=mode, obs_mode=obs_mode)
        env.reset(seed=0)
        a = _held(env, mode)
        for _ in range(5):
            env.step(a)
        t0 = time.perf_counter()
        for _ in range(steps):
            env.step(a)
        out[obs_mode] = (time.perf_counter() - t0) / steps * 1000
        if obs_mode == "state":  # the same Diagram, the slot's update doing nothing
            u = env.unwrapped
            u._source.done = True
            context = u._simulator.get_context()
            t0 = time.perf_counter()
            for _ in range(steps):
                u._simulator.AdvanceTo(context.get_time() + 1.0 / u.rate_hz)
            out["advance"] = (time.perf_counter() - t0) / steps * 1000
    out["frame"] = frame_cost()
    out["state_ratio"] = out["state"] / out["advance"]
    out["rgb_ratio"] = out["state+rgb"] / (out["state"] + cameras * out["frame"])
    return out


def vector_speed(n: int, steps: int) -> float:
    """(d): aggregate steps per second of ``n`` environments in ``n`` processes."""
    envs = gymnasium.make_vec(
        ENV_ID, num_envs=n, vectorization_mode="async", blocks=5, control_mode="ee_delta"
    )
    try:
        envs.reset(seed=list(range(n)))
        a = np.tile(np.r_[np.zeros(6), 1.0].astype(np.float32), (n, 1))
        for _ in range(5):
            envs.step(a)
        t0 = time.perf_counter()
        for _ in range(steps):
            envs.step(a)
        return n * steps / (time.perf_counter() - t0)
    finally:
        envs.close()


def success(
    policy: str, seeds: int, mode: str = "ee_delta", max_steps: int = 2000
) -> tuple[list[bool], list[int]]:
    from cake_drake.plugins import load_attribute  # the plug-in door finds examples/ here

    make = load_attribute(f"examples.{policy}:make", "policy")
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
    p.add_argument("--vector", type=int, default=0, help="(d) up to N environments at once")
    p.add_argument("--only", default="a,b,c,d", help="which parts to run (a,b,c,d)")
    args = p.parse_args()
    parts = set(args.only.split(","))
    print(machine())
    print(renderer_line())  # the GL implementation the cameras render with: a GPU or llvmpipe
    if "c" in parts:
        print("(c) the step's own cost, ms (ratios: goals <= 1.15)")
        for mode in ("ee_delta", "joint_position"):
            o = overhead(mode, args.steps)
            print(
                f"{mode:<16} state {o['state']:.2f}, AdvanceTo alone {o['advance']:.2f} "
                f"-> {o['state_ratio']:.2f}; state+rgb {o['state+rgb']:.2f} vs state + 2 "
                f"frames of {o['frame']:.2f} -> {o['rgb_ratio']:.2f}"
            )
    if "d" in parts and args.vector:
        print(f"(d) AsyncVectorEnv, state, ee_delta, {os.cpu_count()} cores")
        one = None
        n = 1
        while n <= args.vector:
            rate = vector_speed(n, max(50, args.steps // 2))
            one = one or rate
            print(f"  x{n:<3} {rate:8.1f} steps/s   scaling efficiency {rate / (n * one):.0%}")
            n = n * 2 if n * 2 <= args.vector or n == args.vector else args.vector
    if "a" in parts:
        table(args.steps)
    if "b" in parts:
        successes(args.seeds)


def table(steps: int) -> None:
    print(f"(a) environment steps per second, 10 Hz control, 10 ms steps, {steps} steps")
    print(f"{'control mode':<16}{'obs mode':<12}{'env steps/s':>12}{'control periods/s':>19}")
    for mode in ("ee_delta", "joint_position", "joint_chunk"):
        for obs_mode in ("state", "state+rgb"):
            per_s, periods = speed(mode, obs_mode, steps)
            print(f"{mode:<16}{obs_mode:<12}{per_s:>12.1f}{periods:>19.1f}")
    print(f"one 224 x 224 frame: {frame_cost():.1f} ms")


def successes(seeds: int) -> None:
    print(f"(b) success over {seeds} generated problems of 3 to 8 blocks, ee_delta")
    for policy in ("expert_policy", "random_policy"):
        won, steps = success(policy, seeds, max_steps=2000 if "expert" in policy else 300)
        lo, hi = wilson(sum(won), len(won))
        print(
            f"{policy:<16} {sum(won)}/{len(won)} = {np.mean(won):.0%} "
            f"(95 % interval {lo:.0%} to {hi:.0%}), median {int(np.median(steps))} steps"
        )


if __name__ == "__main__":
    main()
