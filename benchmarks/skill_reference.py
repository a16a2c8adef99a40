"""How a learned skill's 10 Hz answers reach computed torque: held as steps, or through the
reference filter (``motion.skill_smooth_s``), on the same held-out problem_5 episodes.

For each setting, the joint-space skills (``models/policies/skills_joint_space``: the
filter smooths joint targets) run under the planner and the execution monitor
(``learned_tower5``'s problem_5, towers placed at random per seed); per setting it
prints the episodes that built the tower, the mean simulated time, how far the stacks
landed off the cube below (median and 95th percentile), and how much the elbow's
commanded torque jumps from one 10 ms sample to the next (median and 99th percentile of
|delta tau|, N m): the chatter a staircase reference causes. ``--figure`` draws the
elbow's torque of the first episode under each setting, one above the other.

    python benchmarks/skill_reference.py --episodes 10 --smooth 0 0.15 \
        --figure docs/images/skill_reference.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from machine import machine

ROOT = Path(__file__).resolve().parents[1]

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
ELBOW = 3  # joint 4
JOINT_SPACE = "package://cake_drake/policies/skills_joint_space"


def episode(seed: int, smooth_s: float):
    """One learned_tower5 episode: its placement drawn from ``seed`` as evaluate's is."""
    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.pipeline import run
    from cake_drake.scenario import load_scenario

    base = load_scenario(LEARNING, "learned_tower5")
    spec = spec_from_scenario(load_scenario(LEARNING, "tower5"))
    scenario = spec.env().episode_scenario(seed)
    scenario.reference, scenario.motion = base.reference, base.motion
    scenario.motion.skills = JOINT_SPACE
    scenario.motion.skill_smooth_s = smooth_s
    scenario.cameras = []
    scenario.outputs.render = False
    return run(scenario, write=False)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--seed", type=int, default=100_000, help="the first held-out seed")
    p.add_argument("--smooth", type=float, nargs="+", default=[0.0, 0.15])
    p.add_argument("--figure", type=Path, help="draw the elbow's torque to this PNG")
    args = p.parse_args()
    print(machine())
    print(f"learned_tower5, held-out seeds {args.seed}..{args.seed + args.episodes - 1}")
    print(f"  {'smooth_s':>8}  {'built':>7}  {'sim s':>6}  {'stacks mm (median/p95)':>22}  "
          f"{'|d tau| elbow N m (median/p99)':>30}")  # fmt: skip
    shown = {}
    for smooth in args.smooth:
        built, sim, places, jumps = 0, [], [], []
        for k in range(args.episodes):
            result = episode(args.seed + k, smooth)
            built += result.success
            sim.append(result.execution.sim_s)
            places += [p["offset_mm"] for p in result.execution.monitoring.get("places", [])]
            logs = result.execution.logs
            jumps.append(np.abs(np.diff(logs.tau_commanded[:, ELBOW])))
            if k == 0:
                shown[smooth] = (logs.t, logs.tau_commanded[:, ELBOW], logs.gravity[:, ELBOW])
        jump = np.concatenate(jumps)
        stacks = (f"{np.median(places):.1f} / {np.percentile(places, 95):.1f}"
                  if places else "-")  # fmt: skip
        print(f"  {smooth:>8g}  {built:>3}/{args.episodes:<3}  {np.mean(sim):>6.1f}  "
              f"{stacks:>22}  {np.median(jump):>14.3f} / {np.percentile(jump, 99):.2f}",
              flush=True)  # fmt: skip
    if args.figure:
        draw(shown, args.figure)
        print(f"figure: {args.figure}")


def draw(shown: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(shown), 1, figsize=(10, 2.6 * len(shown)), sharex=True,
                             squeeze=False)  # fmt: skip
    for ax, (smooth, (t, tau, gravity)) in zip(axes[:, 0], shown.items(), strict=True):
        end = np.searchsorted(t, 12.0)
        ax.plot(t[:end], tau[:end], color="tab:green", lw=0.9, label="torque commanded")
        ax.plot(t[:end], gravity[:end], color="tab:blue", lw=0.9, label="g(q)")
        what = "steps held 0.1 s" if smooth == 0 else f"a filter settling in {smooth:g} s"
        ax.set_title(f"learned skills, joint 4 (elbow): the skill's targets as {what}",
                     fontsize=10)  # fmt: skip
        ax.set_ylabel("N m")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time (s), first held-out episode of problem_5")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
