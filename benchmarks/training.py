"""Training speed: ``python -m cake_drake.train`` against the network alone.

On one recording (``--dataset DIR``, or ``--demos`` demonstrations of ``--task`` recorded
once into ``--work``, with the task's cameras unless ``--no-cameras``) and the task's
recipe (``models/scenarios/learning.yaml``; ``--steps`` overrides its length), prints:

- loading: LeRobot's own dataset per sample (the policy's keys, with its
  ``delta_timestamps``) against the columns in memory (``cake_drake.learning.data.batches``):
  the time to read the recording once, and per sample;
- the network alone: the recipe's policy, its forward, backward and AdamW step on a batch
  already in memory, on the threads ``train`` gives it: steps/s;
- ``train``: two whole processes, of ``--steps`` and a quarter of them: the steady-state
  steps/s from their difference, and the whole recipe's wall time (start-up, the
  checkpoint and all) against the network alone's time for the same steps.

    python benchmarks/training.py --task stack2 --demos 100

``--inputs images`` measures the recipe of a policy that sees (the cameras decoded once,
gathered as uint8 and handed out as floats):

    python benchmarks/training.py --task stack2 --demos 100 --inputs images --steps 1000
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from machine import machine

ROOT = Path(__file__).resolve().parents[1]

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"


def cake(*args: str) -> float:
    """``python -m cake_drake.ARGS`` as a whole process (stopping at a failure); seconds."""
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"python -m {' '.join(args)} failed:\n{r.stderr[-2000:]}")
    return time.perf_counter() - t0


def recording(args) -> Path:
    if args.dataset:
        return args.dataset
    data = args.work / f"{args.task}_demos{args.demos}{'' if args.cameras else '_nocam'}"
    if not (data / "meta" / "info.json").is_file():
        flags = [] if args.cameras else ["--no-cameras"]
        seconds = cake("cake_drake.record", str(LEARNING), "--name", args.task, "--out",
                       str(data), "--episodes", str(args.demos), *flags)  # fmt: skip
        print(f"recorded {args.demos} demonstrations in {seconds:.0f} s: {data}")
    return data


def lerobot_dataset(data: Path, config):
    """LeRobot's dataset of ``data`` with the policy's ``delta_timestamps``."""
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    from cake_drake.learning.data.dataset import REPO_ID

    meta = LeRobotDatasetMetadata(REPO_ID, root=data)
    deltas = resolve_delta_timestamps(config, meta)
    return LeRobotDataset(REPO_ID, root=data, delta_timestamps=deltas, video_backend="pyav")


def per_sample(get, indices) -> float:
    t0 = time.perf_counter()
    get(indices)
    return (time.perf_counter() - t0) / len(indices)


def network_alone(config, dataset, batch_size: int, steps: int) -> float:
    """The recipe's policy trained on one in-memory batch: steps a second."""
    import torch
    from lerobot.policies.factory import make_policy

    policy = make_policy(config, ds_meta=dataset.meta)
    policy.train()
    optimizer = torch.optim.AdamW(policy.parameters(), lr=config.optimizer_lr)
    rng = torch.Generator().manual_seed(0)
    rows = torch.randint(len(dataset), (batch_size,), generator=rng).numpy()
    batch = dataset.gather(rows)
    for k in range(steps + 10):
        if k == 10:  # the first steps warm the allocator up
            t0 = time.perf_counter()
        loss, _ = policy.forward(batch)
        optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), 10.0)
        optimizer.step()
    return steps / (time.perf_counter() - t0)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--task", default="stack2")
    p.add_argument("--demos", type=int, default=100)
    p.add_argument("--dataset", type=Path, help="a recording instead of --task/--demos")
    p.add_argument("--no-cameras", dest="cameras", action="store_false")
    p.add_argument("--steps", type=int, help="training steps (default: the recipe's)")
    p.add_argument("--inputs", help="state | images (default: the recipe's)")
    p.add_argument("--work", type=Path, default=ROOT / "outputs" / "training_benchmark")
    args = p.parse_args()
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    import torch

    from cake_drake.learning.data.batches import ColumnDataset
    from cake_drake.learning.training import train as training
    from cake_drake.scenario import load_scenario

    print(machine())
    data = recording(args)
    recipe = training.for_inputs(load_scenario(LEARNING, args.task).training, args.inputs)
    steps = args.steps or recipe.steps
    keys = training.check(data, Path(tempfile.mkdtemp()) / "x", recipe, "cpu", False)
    import cake_drake.learning.policies.mlp.configuration_mlp  # noqa: F401 - registers cake_mlp

    config = training._policy_config(recipe, "cpu", None)
    base = lerobot_dataset(data, config)
    from lerobot.utils.feature_utils import dataset_to_policy_features

    features = dataset_to_policy_features(base.meta.features)
    config.input_features = {k: features[k] for k in keys}
    config.output_features = {"action": features["action"]}
    base = lerobot_dataset(data, config)
    cameras = len(base.meta.video_keys)
    print(f"recording: {data} ({base.meta.total_episodes} episodes, {len(base)} frames, "
          f"{cameras} cameras); recipe: {recipe.policy} reading {', '.join(keys)}, "
          f"{steps} steps at batch {recipe.batch_size}")  # fmt: skip
    torch.set_num_threads(max(1, len(os.sched_getaffinity(0)) - 1))

    t0 = time.perf_counter()
    fast = ColumnDataset(base, keys)
    load_s = time.perf_counter() - t0
    rng = torch.Generator().manual_seed(1)
    sample = torch.randint(len(base), (128,), generator=rng).tolist()
    lerobot_ms = 1e3 * per_sample(lambda ix: [base[i] for i in ix], sample[:32])
    fast_ms = 1e3 * per_sample(fast.__getitems__, sample)
    print(f"loading: columns read once in {load_s:.2f} s; per sample {fast_ms:.3f} ms, "
          f"LeRobot's dataset {lerobot_ms:.2f} ms ({lerobot_ms / fast_ms:.0f}x)")  # fmt: skip

    alone = network_alone(config, fast, recipe.batch_size, min(steps, 300))
    print(f"network alone: {alone:.1f} steps/s ({1e3 / alone:.1f} ms a step)")

    with tempfile.TemporaryDirectory() as tmp:
        short = max(1, steps // 4)
        walls = {}
        for n in (short, steps):
            out = Path(tmp) / f"s{n}"
            walls[n] = cake("cake_drake.train", str(data), "--out", str(out), "--steps", str(n),
                            "--inputs", recipe.inputs)  # fmt: skip
    steady = (steps - short) / (walls[steps] - walls[short])
    alone_s = steps / alone
    print(f"train: {steady:.1f} steps/s in steady state = {steady / alone:.0%} of the network "
          f"alone; the whole {steps}-step process {walls[steps]:.0f} s = "
          f"{walls[steps] / alone_s:.2f}x the network alone's {alone_s:.0f} s "
          f"({short} steps: {walls[short]:.0f} s)")  # fmt: skip


if __name__ == "__main__":
    main()
