"""The teacher benchmark: the closed-loop expert against the replaying one, clean and
disturbed, through ``CakeDrake/Stack-v0``.

For each action space (``joint_position``, ``ee_delta``) and each expert, ``--episodes``
generated problems of ``--blocks`` cubes (the episode's seed draws the problem):

- clean: the expert acts until the environment ends the episode;
- disturbed: the same, except that from the first step at or after a seeded step at
  which the hand holds a cube, ``--disturb-steps`` random hand moves with the gripper
  open take over (:func:`disturbed_episode`), so the carried cube drops; then the expert
  acts again.

The closed-loop expert is :mod:`cake_drake.learning.expert`; the replaying one is
:class:`ReplayExpert`, the expert the project shipped before it (plan once, run the
classical cake in a simulation of its own, replay that reference by time), kept here
for the comparison. Each row prints successes, the 95 % Wilson interval and the median
steps of the successful episodes.

    python benchmarks/expert.py [--episodes 40] [--blocks 3 8] [--workers 2]
    python benchmarks/expert.py --experts closed-loop --kinds disturbed

``--profile TASK``: where a recording's time goes, on one core: ``--episodes`` of a task
of models/scenarios/learning.yaml recorded as ``record`` does (the same rollout, no
cameras), each step split into the expert's own answer (``act``: reading the facts,
planning, IK, the next target) and the environment's step (the simulation and the
observation), then the episodes written as LeRobot writes them (``record``'s writer).
Prints milliseconds a step and a frame, the shares and the episodes a minute.

    python benchmarks/expert.py --profile tower5 --episodes 10
"""

from __future__ import annotations

import argparse
import copy
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cake_drake.learning.evaluation import wilson

ENV_ID = "cake_drake.gym:CakeDrake/Stack-v0"
#: The first step at which a disturbance may start is drawn from this range.
ONSET = (20, 120)


# --- the replaying expert (the project's expert before the closed-loop one) ---------------


class ReplayExpert:
    """Plans once, runs the classical cake in a simulation of its own at reset, and replays
    that reference: by time in ``joint_position``, in ``ee_delta`` by a clock that waits
    while the hand is behind. It never looks at the cubes again."""

    def __init__(self, slow: float = 0.35) -> None:
        from cake_drake.geometric.ik import Kinematics

        self.slow = slow
        self.kin = Kinematics()
        self.reason = None

    def reset(self, task, seed: int) -> None:
        from cake_drake.pipeline import run
        from cake_drake.scenario import Planned

        scenario = copy.deepcopy(task.scenario)
        scenario.reference = Planned()
        scenario.cameras = []
        scenario.seed = seed
        timing = scenario.motion.timing
        timing.velocity_fraction *= self.slow
        timing.acceleration_fraction *= self.slow
        logs = run(scenario, write=False).execution.logs
        self.t, self.q = logs.t, logs.q_d
        self.width = 2 * logs.fingers_d.reshape(len(logs.t), -1)[:, 0]
        self.end = float(self.t[-1])
        self.space, self.rate = task.action_space, task.rate_hz
        self.steps, self.tau = 0, 0.0

    def reference(self, t: float) -> tuple[np.ndarray, float]:
        q = np.array([np.interp(t, self.t, self.q[:, j]) for j in range(7)])
        return q, float(np.interp(t, self.t, self.width))

    def act(self, observation: dict):
        from pydrake.math import RollPitchYaw

        from cake_drake.learning.policies.expert import measured
        from cake_drake.policy.spaces import EE_STEP, GRIPPER_MAX

        step, self.steps = self.steps, self.steps + 1
        if self.space == "joint_position":
            t = (step + 1) / self.rate
            if t > self.end + 1.0 / self.rate:
                return None, True
            q, width = self.reference(t)
            return np.r_[q, width]
        X_now = measured(observation, ()).X_WG
        X_tau = self.kin.pose(self.reference(self.tau)[0])
        behind = np.linalg.norm(X_tau.translation() - X_now.translation())
        turned = X_tau.rotation().multiply(X_now.rotation().inverse()).ToAngleAxis().angle()
        if behind < 0.01 and turned < 0.05:
            self.tau += 1.0 / self.rate
        if self.tau > self.end + 1.0 / self.rate:
            return None, True
        q, width = self.reference(self.tau)
        X_ref = self.kin.pose(q)
        d_rot = X_ref.rotation().multiply(X_now.rotation().inverse())
        delta = np.r_[X_ref.translation() - X_now.translation(), RollPitchYaw(d_rot).vector()]
        return np.r_[np.clip(delta, -EE_STEP, EE_STEP), min(width / GRIPPER_MAX, 1.0)]


def make_expert(which: str):
    """``closed-loop`` (the project's expert) or ``replay`` (:class:`ReplayExpert`)."""
    if which == "replay":
        return ReplayExpert()
    from cake_drake.learning.policies.expert import make

    return make()


# --- one episode --------------------------------------------------------------------------


@dataclass(frozen=True)
class Outcome:
    seed: int
    success: bool
    steps: int
    disturbed_at: int | None  # the step the disturbance began (None: none took place)
    dropped: bool  # a cube was in the hand before the disturbance and not after it
    reason: str  # why the expert stopped, if it did; else the environment's verdict


def held(obs: dict, cubes) -> str | None:
    """The cube in the hand, read from the observation as the expert and the monitor do."""
    from cake_drake.learning.policies.expert import measured
    from cake_drake.world.facts import held_cube

    m = measured(obs, cubes)
    return held_cube(m.cubes, m.X_WG, m.width / 2)


def random_move(space: str, obs: dict, rng: np.random.Generator) -> np.ndarray:
    """One random hand move with the gripper open: a full ``ee_delta`` step, or the joints
    moved by up to 0.1 rad each."""
    if space == "ee_delta":
        from cake_drake.policy.spaces import EE_STEP

        return np.r_[rng.uniform(-EE_STEP, EE_STEP), 1.0]
    q = np.asarray(obs["state"][:7], float)
    return np.r_[q + rng.uniform(-0.1, 0.1, 7), 0.08]


def disturbed_episode(
    space: str,
    seed: int,
    expert,
    blocks: tuple[int, int] = (3, 8),
    disturb_steps: int = 6,
    problem: str | None = None,
    max_steps: int = 1200,
) -> Outcome:
    """One episode of ``expert`` through the environment reset with ``seed``; with
    ``disturb_steps`` > 0, from the first step at or after a step drawn from :data:`ONSET`
    (by ``seed``) at which a cube is in the hand, that many :func:`random_move` steps
    replace the expert's."""
    import gymnasium

    env = gymnasium.make(
        ENV_ID, blocks=blocks, problem=problem, control_mode=space, max_steps=max_steps
    )
    obs, info = env.reset(seed=seed)
    task = env.unwrapped.policy_task
    expert.reset(task, seed)
    rng = np.random.default_rng([seed, 36])
    onset = int(rng.integers(*ONSET)) if disturb_steps > 0 else None
    disturbed_at, dropped, steps, said_done = None, False, 0, False
    terminated = truncated = False
    while not (terminated or truncated):
        if disturbed_at is None and onset is not None and steps >= onset and held(obs, task.cubes):
            disturbed_at, before = steps, held(obs, task.cubes)
            for _ in range(disturb_steps):
                obs, _, terminated, truncated, info = env.step(random_move(space, obs, rng))
                steps += 1
                if terminated or truncated:
                    break
            dropped = held(obs, task.cubes) != before
            continue
        answer = expert.act(obs)
        action, done = answer if isinstance(answer, tuple) else (answer, False)
        if action is None:
            said_done = True
            break
        obs, _, terminated, truncated, info = env.step(action)
        steps += 1
    reason = getattr(expert, "reason", None)
    if info["is_success"]:
        reason = "goal reached"
    elif reason is None:
        reason = (
            "the expert said done"
            if said_done
            else "a cube left the table"
            if terminated
            else f"not done after {steps} steps"
        )
    return Outcome(seed, bool(info["is_success"]), steps, disturbed_at, dropped, reason)


# --- where a recording's time goes --------------------------------------------------------

#: Seconds in the profiled expert's ``act`` (this process: the rollout runs here).
ACT_S = [0.0]


def timed_expert(**options):
    """The closed-loop expert, its ``act`` timed into :data:`ACT_S` (a policy factory)."""
    import time

    from cake_drake.learning.policies.expert import make

    expert = make(**options)
    act = expert.act

    def timed(observation):
        t0 = time.perf_counter()
        try:
            return act(observation)
        finally:
            ACT_S[0] += time.perf_counter() - t0

    expert.act = timed
    return expert


def profile(task: str, episodes: int) -> None:
    import tempfile
    import time
    from dataclasses import replace

    from cake_drake.learning.data import dataset
    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.learning.rollout import rollout
    from cake_drake.scenario import load_scenario

    learning = Path(__file__).resolve().parents[1] / "models" / "scenarios" / "learning.yaml"
    spec = spec_from_scenario(load_scenario(learning, task))
    me = sys.modules[__name__].__name__  # "__main__" when run as a script
    spec = replace(spec, cameras=(), policy=f"{me}:timed_expert")
    kept, wall, steps = [], 0.0, 0
    rollout(spec, 10_000)  # imports and first calls, not counted
    ACT_S[0] = 0.0
    for seed in range(episodes):
        t0 = time.perf_counter()
        ep = rollout(spec, seed)
        wall += time.perf_counter() - t0
        steps += ep.steps
        kept += [ep] if ep.success else []
    act = ACT_S[0]
    with tempfile.TemporaryDirectory() as tmp:
        dataset.write(Path(tmp) / "warm", kept[:1], spec.rate_hz, spec.control_mode, ())
        t0 = time.perf_counter()
        frames = dataset.write(Path(tmp) / "d", kept, spec.rate_hz, spec.control_mode, ())
        write = time.perf_counter() - t0
    per = 1000.0 / steps
    print(f"{task}: {episodes} episodes recorded by the closed-loop expert on one core, "
          f"{len(kept)} kept, {steps / episodes:.0f} steps an episode")  # fmt: skip
    print(f"  a step {wall * per:.2f} ms: the expert's own answer {act * per:.2f} ms "
          f"({act / wall:.0%}), the environment and the rest {(wall - act) * per:.2f} ms "
          f"({1 - act / wall:.0%})")  # fmt: skip
    print(f"  writing (LeRobot's writer): {1000 * write / max(frames, 1):.2f} ms a frame, "
          f"{write / (wall + write):.0%} of the recording on one core")  # fmt: skip
    print(f"  {60 * episodes / (wall + write):.1f} episodes a minute on one core, writing included")


# --- the table ----------------------------------------------------------------------------


def _one(args) -> Outcome:
    space, which, seed, blocks, disturb = args
    try:
        return disturbed_episode(space, seed, make_expert(which), blocks, disturb)
    except Exception as e:  # a failed episode is a row's failure, not the table's end
        return Outcome(seed, False, 0, None, False, f"raised {type(e).__name__}: {e}")


def main() -> None:
    from machine import machine  # benchmarks/machine.py

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--blocks", type=int, nargs=2, default=(3, 8), metavar=("LO", "HI"))
    parser.add_argument("--disturb-steps", type=int, default=6)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--spaces", nargs="+", default=["joint_position", "ee_delta"])
    parser.add_argument("--experts", nargs="+", default=["replay", "closed-loop"])
    parser.add_argument(
        "--kinds",
        nargs="+",
        default=["clean", "disturbed"],
        choices=["clean", "disturbed"],
        help="which rows of each expert",
    )
    parser.add_argument("--profile", metavar="TASK", help="where a recording's time goes")
    args = parser.parse_args()
    print(machine())
    if args.profile:
        profile(args.profile, args.episodes)
        return
    print(
        f"{args.episodes} generated problems of {args.blocks[0]} to {args.blocks[1]} blocks "
        f"per row (seeds 0..{args.episodes - 1}); disturbed: {args.disturb_steps} random hand "
        "moves, gripper open, once a cube is in the hand"
    )
    rows = [
        (space, which, disturb)
        for space in args.spaces
        for which in args.experts
        for kind, disturb in (("clean", 0), ("disturbed", args.disturb_steps))
        if kind in args.kinds
    ]
    jobs = [
        (space, which, seed, tuple(args.blocks), disturb)
        for space, which, disturb in rows
        for seed in range(args.episodes)
    ]
    with ProcessPoolExecutor(args.workers) as pool:
        outcomes = list(pool.map(_one, jobs, chunksize=1))
    print()
    print("| action space | expert | episodes | success | 95 % interval | median steps |")
    print("|---|---|---|---|---|---|")
    for k, (space, which, disturb) in enumerate(rows):
        got = outcomes[k * args.episodes : (k + 1) * args.episodes]
        n = len(got)
        wins = sum(o.success for o in got)
        lo, hi = wilson(wins, n)
        steps = [o.steps for o in got if o.success]
        kind = "disturbed" if disturb else "clean"
        dropped = sum(o.dropped for o in got)
        note = f" ({dropped} dropped a cube)" if disturb else ""
        print(
            f"| {space} | {which} | {kind}{note} | {wins}/{n} | {lo:.0%} to {hi:.0%} "
            f"| {int(np.median(steps)) if steps else '-'} |"
        )
        reasons: dict[str, list[int]] = {}
        for o in got:
            if not o.success:
                reasons.setdefault(o.reason[:80], []).append(o.seed)
        for reason, seeds in sorted(reasons.items()):
            print(f"|   | failed: {reason} | seeds {', '.join(map(str, seeds))} | | | |")


if __name__ == "__main__":
    main()
