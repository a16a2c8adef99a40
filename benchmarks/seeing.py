"""What a policy that sees saw: one held-out episode of a checkpoint trained with
``--inputs images``, its two cameras' frames at the moments that matter beside the joint
targets it sent.

Runs the checkpoint (``--policy``, default the shipped ``models/policies/stack2_pixels``)
on ``--task`` (default stack2) from ``--seed`` in the Gym environment, with the task's
cameras, and draws ``--out`` (default ``docs/images/stack2_pixels_episode.png``):

- top rows: the scene and wrist cameras at the episode's start, the grasp (the gripper's
  target closes), the release (it opens again) and the end: what the policy read there;
- bottom: the arm's seven joint targets and the gripper's width target over the episode,
  the grasp and release marked.

Prints the episode's verdict. ``--seed`` a failing seed draws a failure.

    python benchmarks/seeing.py --seed 100001
    python benchmarks/seeing.py --seed 100000 --out docs/images/stack2_pixels_failure.png
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
SHIPPED = ROOT / "models" / "policies" / "stack2_pixels"


def moments(actions: np.ndarray) -> dict[str, int]:
    """The steps worth a look: start, grasp (the width target first falls below half its
    opening), release (it rises again after that), end."""
    width = actions[:, 7]
    half = 0.5 * (width.max() + width.min())
    closed = np.flatnonzero(width < half)
    grasp = int(closed[0]) if len(closed) else len(width) // 3
    after = np.flatnonzero((width >= half) & (np.arange(len(width)) > grasp))
    release = int(after[0]) if len(after) else 2 * len(width) // 3
    return {"start": 0, "grasp": grasp, "release": release, "end": len(width) - 1}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", type=Path, default=SHIPPED)
    p.add_argument("--task", default="stack2")
    p.add_argument("--seed", type=int, default=100_001)
    p.add_argument("--out", type=Path, default=ROOT / "docs/images/stack2_pixels_episode.png")
    args = p.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.learning.rollout import rollout
    from cake_drake.scenario import CHECKPOINT_POLICY, load_scenario

    scenario = load_scenario(LEARNING, args.task)
    spec = replace(
        spec_from_scenario(scenario),
        policy=CHECKPOINT_POLICY,
        options={"path": str(args.policy.resolve()), "device": "cpu"},
    )
    episode = rollout(spec, args.seed, record=True)
    verdict = "goal reached" if episode.success else f"failed: {episode.reason}"
    print(f"{args.task}, seed {args.seed}: {verdict} in {episode.steps} steps")
    at = moments(episode.actions)
    cameras = list(episode.images)
    fig = plt.figure(figsize=(2.1 * len(at), 2.1 * len(cameras) + 2.6), dpi=110)
    grid = fig.add_gridspec(len(cameras) + 1, len(at), height_ratios=[1] * len(cameras) + [1.3])
    for row, name in enumerate(cameras):
        for col, (label, step) in enumerate(at.items()):
            ax = fig.add_subplot(grid[row, col])
            ax.imshow(episode.images[name][step], interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(f"{label} (step {step})", fontsize=9)
            if col == 0:
                ax.set_ylabel(name, fontsize=9)
    ax = fig.add_subplot(grid[len(cameras), :])
    t = np.arange(len(episode.actions)) / spec.rate_hz
    for j in range(7):
        ax.plot(t, episode.actions[:, j], lw=1.2, label=f"q{j + 1}")
    ax.set_ylabel("joint target (rad)", fontsize=9)
    ax.set_xlabel("time (s)", fontsize=9)
    fingers = ax.twinx()
    fingers.plot(t, episode.actions[:, 7] * 1000, "k--", lw=1.2, label="gripper")
    fingers.set_ylabel("gripper width target (mm)", fontsize=9)
    for label in ("grasp", "release"):
        ax.axvline(at[label] / spec.rate_hz, color="0.5", lw=0.8, ls=":")
        ax.text(at[label] / spec.rate_hz, ax.get_ylim()[1], f" {label}", fontsize=8, va="top")
    ax.legend(loc="lower left", ncol=8, fontsize=7, frameon=False)
    fig.suptitle(
        f"{args.policy.name} on {args.task}, held-out seed {args.seed}: {verdict}\n"
        "it reads the joints and these frames, no cube pose",
        fontsize=10,
    )
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
