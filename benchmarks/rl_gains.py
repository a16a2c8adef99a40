"""The §4.3 controller as a policy: PPO chooses computed torque's gains, per joint, for
0.5 kg cubes the controller's model does not know, and is measured against the hand-tuned
Kp 100 / Kd 20 and the learned residual on the residual study's held-out problems.

The MDP is one step long (a contextual bandit with one context): the action is 14 numbers
from -1 to 1, each joint's Kp = 100 x 4^a (25 to 400) and Kd = 20 x 4^a (5 to 80); the
step runs a whole training problem of ``benchmarks/residual.py`` (problem_5 and generated
three- to six-cube problems, drawn per episode) under ``InverseDynamicsController`` with
those gains; the reward is minus the elbow's and the wrist's RMS error while carrying
(mrad, over 10), minus 5 when the goal is not reached. Stable-Baselines3's PPO learns it
with two environments side by side, for ``--minutes`` of wall time. Then the policy's
mean answer runs the four held-out problems, beside Kp 100 / Kd 20 with no correction
and with the learned residual (``models/residuals/cubes_0.5kg``).

    python benchmarks/rl_gains.py --minutes 30
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium import spaces
from machine import machine
from residual import HELD_OUT, TRAIN, metrics, scenario

ROOT = Path(__file__).resolve().parents[1]

RESIDUAL = ROOT / "models" / "residuals" / "cubes_0.5kg"
KP, KD, RANGE = 100.0, 20.0, 4.0


def gains(action) -> tuple[list[float], list[float]]:
    a = np.clip(np.asarray(action, float), -1.0, 1.0)
    return list(KP * RANGE ** a[:7]), list(KD * RANGE ** a[7:])


def run_with(problem, kp, kd, residual: Path | None = None) -> dict:
    from cake_drake.pipeline import run

    s = scenario(problem, 20.0, "learned" if residual else "none", residual, None)
    s.controller.kp, s.controller.kd = list(kp), list(kd)
    try:
        return metrics(run(s, write=False))
    except Exception as e:  # unstable gains: the run ends in an error, which is a failure
        return {"success": False, "peak": np.full(2, np.nan), "rms": np.full(2, np.nan),
                "error": str(e).splitlines()[0][:80]}  # fmt: skip


class GainsEnv(gymnasium.Env):
    """One training problem a step, run with the gains the action names."""

    def __init__(self) -> None:
        self.observation_space = spaces.Box(0.0, 1.0, (1,), np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, (14,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.ones(1, np.float32), {}

    def step(self, action):
        problem = TRAIN[int(self.np_random.integers(len(TRAIN)))][1]
        m = run_with(problem, *gains(action))
        rms = m["rms"]
        cost = 50.0 if not np.all(np.isfinite(rms)) else float(rms.sum() * 1e3 / 10.0)
        reward = -cost - (0.0 if m["success"] else 5.0)
        return np.ones(1, np.float32), reward, True, False, {"is_success": bool(m["success"])}


def train(minutes: float, seed: int):
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import SubprocVecEnv

    torch.set_num_threads(1)
    venv = SubprocVecEnv([lambda: Monitor(GainsEnv())] * 2, start_method="spawn")
    deadline = time.perf_counter() + 60.0 * minutes
    rewards: list[float] = []

    class Clock(BaseCallback):
        def _on_step(self) -> bool:
            for info in self.locals.get("infos", ()):
                if "episode" in info:
                    rewards.append(float(info["episode"]["r"]))
            if len(rewards) and len(rewards) % 16 == 0:
                print(f"  {len(rewards)} episodes, mean reward of the last 16 "
                      f"{np.mean(rewards[-16:]):.2f}", flush=True)  # fmt: skip
            return time.perf_counter() < deadline

    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, n_epochs=10, learning_rate=3e-3,
                gamma=0.0, policy_kwargs={"net_arch": [32, 32], "log_std_init": -0.7},
                seed=seed, device="cpu", verbose=0)  # fmt: skip
    model.learn(total_timesteps=1_000_000, callback=Clock())
    venv.close()
    mean, _ = model.predict(np.ones(1, np.float32), deterministic=True)
    return mean, len(rewards)


def row(label: str, got: list[dict]) -> str:
    peak = np.nanmax([g["peak"] for g in got], axis=0) * 1e3
    rms = np.nanmax([g["rms"] for g in got], axis=0) * 1e3
    goals = sum(g["success"] for g in got)
    return (f"  {label:<34} {peak[0]:>10.1f} {peak[1]:>10.1f} {rms[0]:>9.1f} {rms[1]:>9.1f} "
            f"{goals:>3}/{len(got)}")  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=30.0, help="PPO's wall-time budget")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    print(machine())
    t0 = time.perf_counter()
    action, episodes = train(args.minutes, args.seed)
    kp, kd = gains(action)
    print(f"PPO: {episodes} episodes (runs) in {(time.perf_counter() - t0) / 60:.1f} min; "
          f"its gains: Kp {np.round(kp, 0).tolist()}, Kd {np.round(kd, 1).tolist()}")  # fmt: skip
    print(f"\n{len(HELD_OUT)} held-out problems, 0.5 kg cubes; errors while carrying in mrad "
          "(worst problem)")  # fmt: skip
    print(f"  {'controller':<34} {'peak elbow':>10} {'peak wrist':>10} {'rms elbow':>9} "
          f"{'rms wrist':>9} {'goals':>6}")  # fmt: skip
    rows = {
        "Kp 100 / Kd 20 (hand-tuned)": ([KP] * 7, [KD] * 7, None),
        "Kp 100 / Kd 20 + learned residual": ([KP] * 7, [KD] * 7, RESIDUAL),
        "PPO's gains": (kp, kd, None),
    }
    for label, (p_, d_, residual) in rows.items():
        got = [run_with(problem, p_, d_, residual) for _, problem in HELD_OUT]
        print(row(label, got), flush=True)
    print(f"{time.perf_counter() - t0:.0f} s in all")


if __name__ == "__main__":
    main()
