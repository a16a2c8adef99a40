"""Learning benchmark: the results table of the learning tasks, through the project's own
commands (record, train, evaluate), on held-out seeds with 95 % Wilson intervals.

For each task of ``models/scenarios/learning.yaml`` named in ``--tasks``:

- ``expert``: the demonstrator (the task's ``!Policy``), evaluated;
- ``random``: uniform random actions (``examples.random_policy:make``), the floor;
- for each ``--policies`` x ``--demos``: ``record`` that many demonstrations (no cameras:
  state policies), ``train`` the task's recipe with that LeRobot policy, ``evaluate`` the
  checkpoint.

Demonstrations use seeds 0, 1, 2, ...; every row is evaluated on the same ``--episodes``
held-out seeds from ``--eval-seed`` (default 100000). Recordings and checkpoints are kept
in ``--work`` and reused when the script runs again (delete a folder to redo it). Prints
one row per policy: success, the interval, training minutes and steps/s, and the
evaluation's episodes per minute.

    python benchmarks/learning.py --tasks stack2 --demos 100 300 --policies act

Each trained row is followed by its profile: ``train``'s phases (loading the recording,
answering batches, the network's updates, the checkpoint, from its ``train.json``), the
rest of its whole process (start-up) and the evaluation's wall time. Each task's
demonstrations are one recording (``--work/TASK_pool``, grown with ``record --resume``);
a row of N demonstrations takes its first N seeds.

``--all``: the whole table of docs/learning.md (every task x the recipe from 100, 300 and
1,000 demonstrations; stack2 x ACT and Diffusion Policy; BC, DART and DAgger on tower5
and blocks3), then the total time: this run's (cached rows are not redone) and the
table's from nothing (the sum of every recording, training and evaluation it used, as
long as each took when it was made).

``--jobs N`` trains N rows side by side (their datasets made first), a comparison's BC
and DART, and runs N comparisons side by side. ``train`` gives the network every core
but one, so on two cores one training leaves a core idle: the default is 2 there, 1 on
larger machines.

``--compare``: BC, DART and DAgger at equal numbers of expert-labelled frames, per task.
DAgger records ``--start-demos`` demonstrations and runs ``--rounds`` rounds of
``--per-round`` rollouts (``train --dagger``, ``--beta``); BC then trains on the first
plain demonstrations, and DART on the first noisy ones (``record --noise``), whose frames
reach DAgger's expert-labelled frames (from a pool of ``--pool`` recorded episodes each).
Prints each row's frames and its success on the held-out seeds with the interval.

    python benchmarks/learning.py --compare --tasks tower5 blocks3 --policies act

``--pixels N``: a policy that sees. ``record`` N demonstrations of each task with its
two cameras, then train on that one recording the state recipe and the image recipe
(``--inputs images``: the joints, the cameras and the goal, no cube pose), and evaluate
each on the same held-out seeds; ``--views TASK...`` adds, for those tasks, the image
recipe on the scene camera alone and on the wrist camera alone. Prints the training's
minutes, steps/s and peak memory per row.

    python benchmarks/learning.py --pixels 300 --tasks stack2 tower3 --views stack2

``--skills N``: learned skills under the planner. ``record`` N demonstrations of the
``skills`` task (generated five-cube problems), ``train`` its recipe (``--inputs skill``),
then ``evaluate`` the skills in place of each task's demonstrator (the planner's plan, the
execution monitor, the skills as the geometric layer), with the classical geometric
layer on the same episodes beside each row; ``--sizes`` adds generated problems of those
sizes, which no demonstration had. ``--skill-tasks`` names the recording tasks (``skills``:
joint targets; ``skills_hand``: moves of the hand), ``--joint-space`` adds the joint-space skills
kept in ``models/policies/skills_joint_space``, as trained and with their action chunks
ensembled (``motion.skill_ensemble``).
Each row says how often the monitor's repeats and replans rescued an episode, how far the
stacks were set off the cube below (median/95th percentile) and the mean simulated time.

    python benchmarks/learning.py --skills 400 --tasks tower5 blocks3 --sizes 6 8
    python benchmarks/learning.py --skills 800 --skill-tasks skills skills_hand --tasks tower5
    python benchmarks/learning.py --skills 800 --skill-tasks skills+skills_tall:300
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from machine import machine

from cake_drake.learning.evaluation import wilson

ROOT = Path(__file__).resolve().parents[1]

LEARNING = ROOT / "models" / "scenarios" / "learning.yaml"
RANDOM = "examples.random_policy:make"

#: What every row used so far cost when it was made (seconds, whole processes), cached or
#: not: each pool's recording once, each training and each evaluation; and what is unknown
#: (made before its time was kept). ``--all`` adds it up: the table's time from nothing.
SPENT: dict[str, float] = {}
UNKNOWN: set[str] = set()


def spent(what: str, seconds: float | None) -> None:
    if seconds is None:
        UNKNOWN.add(what)
    else:
        SPENT[what] = seconds


#: Runs one command; prints its peak memory (the largest of its processes), in MiB.
PEAK = """
import resource, subprocess, sys
code = subprocess.run(sys.argv[1:]).returncode
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, file=sys.stderr)
sys.exit(code)
"""


def cake(command: str, *args: str, peak: dict | None = None) -> float:
    """Run ``python -m cake_drake.COMMAND ARGS`` (stopping at a failure); its wall time (s).
    With ``peak``, its peak memory (MiB) goes to ``peak["peak_mib"]``."""
    t0 = time.perf_counter()
    cmd = [sys.executable, "-m", f"cake_drake.{command}", *args]
    if peak is not None:
        cmd = [sys.executable, "-c", PEAK, *cmd]
    r = subprocess.run(
        cmd, cwd=ROOT, capture_output=True, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    if r.returncode != 0:
        sys.exit(f"python -m cake_drake.{command} {' '.join(args)} failed:\n{r.stderr[-2000:]}")
    if peak is not None:
        peak["peak_mib"] = float(r.stderr.strip().splitlines()[-1])
    return time.perf_counter() - t0


def is_skill_checkpoint(policy: str) -> bool:
    """Whether ``policy`` is a training folder of a learned skill."""
    from cake_drake.learning.policies.lerobot_checkpoint import is_skill, model_folder
    from cake_drake.learning.policies.lerobot_checkpoint import read_checkpoint as _config

    return Path(policy).is_dir() and is_skill(_config(model_folder(Path(policy))))


def evaluate(task: str, policy: str, out: Path, episodes: int, seed: int) -> dict:
    """``evaluate``'s summary (run if absent), with its whole process's wall time."""
    summary, wall = out / "summary.json", out.parent / f"{out.name}_wall_s.json"
    if not summary.is_file():
        args = ["--suite", str(LEARNING), "--name", task, "--episodes", str(episodes)]
        if not is_skill_checkpoint(policy):  # a skill's episodes are whole runs: no frames
            args += ["--frames", "8"]  # failures.png: how the first failures end
        seconds = cake("evaluate", policy, *args, "--seed", str(seed), "--out", str(out))
        wall.write_text(json.dumps(seconds))
    made = json.loads(summary.read_text())
    seconds = json.loads(wall.read_text()) if wall.is_file() else None
    spent(f"evaluating {out}", seconds)
    return {**made, "wall_s": seconds}


def profile(train: dict, evaluation: dict) -> str:
    """Where a row's time went: train's phases (its train.json), the rest of its whole
    process (start-up: imports, the policy's set-up; LeRobot's logging), the evaluation."""
    phases = train.get("phases_s")
    if not phases:
        return "    phases: not recorded (a training from before train.json kept them)"
    inner = sum(phases[k] for k in ("loading", "batches", "network", "checkpoint"))
    rest = train["train_s"] - inner
    text = " · ".join(f"{k} {phases[k]:.1f} s" for k in ("loading", "batches", "network",
                                                         "checkpoint"))  # fmt: skip
    ev = evaluation.get("wall_s")
    ev = f"{ev:.0f} s for {evaluation['episodes']} episodes" if ev else "-"
    return f"    phases: {text} · start-up and the rest {rest:.1f} s · evaluation {ev}"


def recorded(task: str, episodes: int, work: Path, noise: float = 0.0) -> Path:
    """The pool of ``task``'s recorded episodes (seeds 0, 1, ...; noised or not), grown to
    ``episodes`` when it has fewer (``record --resume``): one recording per task and
    noise, from which every row takes its first demonstrations."""
    data = work / (f"{task}_pool" + (f"_noise{noise:g}" if noise else ""))
    report, took = data / "report.json", work / f"{data.name}_record_s.json"
    before = json.loads(took.read_text()) if took.is_file() else None
    if report.is_file() and json.loads(report.read_text())["tried"] >= episodes:
        spent(f"recording {data}", before)
        return data
    extra = ["--noise", str(noise)] if noise else []
    seconds = cake("record", str(LEARNING), "--name", task, "--out", str(data), "--episodes",
                   str(episodes), "--no-cameras", "--resume", *extra)  # fmt: skip
    if before is not None or not report.is_file():  # its whole recording's time is known
        took.write_text(json.dumps((before or 0.0) + seconds))
    else:
        took.unlink(missing_ok=True)
    spent(f"recording {data}", (before or 0.0) + seconds if took.is_file() else None)
    noised = f" (noise {noise:g})" if noise else ""
    print(f"recorded {task} to {episodes} episodes{noised} in {seconds / 60:.1f} min", flush=True)
    return data


@functools.cache
def recipe(task: str) -> dict:
    """``task``'s training recipe as learning.yaml had it the first time it was asked (read
    once: an edit of the file while the benchmark runs changes nothing mid-table)."""
    from dataclasses import asdict

    from cake_drake.scenario import load_scenario

    return asdict(load_scenario(LEARNING, task).training)


def recipe_tag(task: str, policy: str | None = None) -> str:
    """A recipe's length, in the names of what is trained with it (a recipe changed in
    learning.yaml trains anew); for a policy the recipe trains through its part (ACT,
    Diffusion Policy), that part's batch, learning rate and denoising passes too."""
    r = recipe(task)
    tag = f"steps{r['steps']}_batch{r['batch_size']}"
    part = r.get(policy) if policy in ("act", "diffusion") and policy != r["policy"] else None
    if part:
        tag = f"steps{part['steps'] or r['steps']}_batch{part['batch_size'] or r['batch_size']}"
        tag += f"_lr{part['lr']:g}" if part["lr"] else ""
        tag += f"_ddim{part['inference_steps']}" if part.get("inference_steps") else ""
    return tag


def demonstrations(task: str, demos: int, work: Path) -> Path:
    """A dataset of the first ``demos`` seeds' kept demonstrations of ``task`` (taken from
    its pool, recorded if absent; the task's episodes start at its scenario's seed),
    carrying the task's recipe as learning.yaml has it."""
    from cake_drake.scenario import load_scenario

    pool = recorded(task, demos, work)
    data = work / f"{task}_demos{demos}_{recipe_tag(task)}"
    subset(pool, data, seeds_below=load_scenario(LEARNING, task).seed + demos)
    return data


def mixed(parts: list[tuple[str, int]], work: Path) -> Path:
    """One dataset of several tasks' demonstrations (``parts``: each task and how many of
    its first seeds), its report the first task's (its spec, its recipe) with every
    episode counted; made once."""
    from cake_drake.learning.data import dataset
    from cake_drake.learning.data.recording import load_episode as _load

    tag = "+".join(f"{task}{n}" for task, n in parts)
    out = work / f"{tag}_{recipe_tag(parts[0][0])}"
    if (out / "report.json").is_file():
        return out
    sources = [demonstrations(task, n, work) for task, n in parts]
    reports = [json.loads((src / "report.json").read_text()) for src in sources]
    spaces = {r["control_mode"] for r in reports}
    if len(spaces) > 1:
        sys.exit(
            f"{tag}: demonstrations of {' and '.join(sorted(spaces))} actions; one "
            "dataset holds one action space"
        )
    files = [(src, seed) for src, r in zip(sources, reports, strict=True) for seed in r["seeds"]]
    rows = [json.loads((src / "episodes" / f"ep_{seed}.json").read_text()) for src, seed in files]
    episodes = (_load(src / "episodes" / f"ep_{seed}.npz", row, images=False)
                for (src, seed), row in zip(files, rows, strict=True))  # fmt: skip
    first = reports[0]
    written = dataset.write(out, episodes, first["fps"], first["control_mode"], ())
    (out / "episodes").mkdir()
    for src, seed in files:
        for name in (f"ep_{seed}.npz", f"ep_{seed}.json"):
            os.link(src / "episodes" / name, out / "episodes" / name)
    report = {
        **first,
        "episodes": len(rows),
        "frames": written,
        "seeds": [s for _, s in files],
        "failed": [f for r in reports for f in r.get("failed", [])],
        "tried": sum(r["tried"] for r in reports),
        "parts": [list(p) for p in parts],
    }
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return out


def trained(task: str, policy: str, demos: int, work: Path) -> tuple[Path, dict]:
    """The checkpoint of ``policy`` on ``demos`` demonstrations of ``task`` (made if absent),
    and the training's figures. ``task`` may join several tasks' demonstrations,
    ``TASK+TASK:N``: the first's ``demos``, then N of each other (:func:`mixed`)."""
    if "+" in task:
        first, *others = task.split("+")
        parts = [(first, demos)] + [(t.split(":")[0], int(t.split(":")[1])) for t in others]
        data = mixed(parts, work)
        run = work / f"{data.name}_{policy}"
        return run, train_once(data, run, policy)
    data = demonstrations(task, demos, work)
    run = work / f"{task}_{policy}_demos{demos}_{recipe_tag(task, policy)}"
    return run, train_once(data, run, policy)


def subset(pool: Path, out: Path, frames: int | None = None, seeds_below: int | None = None):
    """A dataset at ``out`` of ``pool``'s kept episodes in seed order: those of seeds below
    ``seeds_below``, or the first whose frames reach ``frames`` (all of them when they do
    not); its report. Made once: an existing ``out`` is kept."""
    from cake_drake.learning.data import dataset
    from cake_drake.learning.data.recording import load_episode as _load

    if (out / "report.json").is_file():  # its episodes as made; the recipe as it is now
        report = json.loads((out / "report.json").read_text())
        if report.get("training") != recipe(report["task"]):
            report["training"] = recipe(report["task"])
            (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
        return report
    report = json.loads((pool / "report.json").read_text())
    rows, total = [], 0
    for seed in sorted(report["seeds"]):
        if (frames is not None and total >= frames) or (
            seeds_below is not None and seed >= seeds_below
        ):
            break
        row = json.loads((pool / "episodes" / f"ep_{seed}.json").read_text())
        rows.append(row)
        total += row["steps"]
    episodes = (_load(pool / "episodes" / f"ep_{r['seed']}.npz", r, images=False) for r in rows)
    written = dataset.write(out, episodes, report["fps"], report["control_mode"], ())
    seeds = [r["seed"] for r in rows]
    last = seeds_below if seeds_below is not None else max(seeds, default=-1) + 1
    failed = [f for f in report.get("failed", []) if f["seed"] < last]
    # The episodes themselves too (linked), as record keeps them: train --dagger reads them.
    (out / "episodes").mkdir()
    for seed in seeds:
        for name in (f"ep_{seed}.npz", f"ep_{seed}.json"):
            os.link(pool / "episodes" / name, out / "episodes" / name)
    report = {**report, "episodes": len(rows), "frames": written, "seeds": seeds,
              "cameras": [], "failed": failed, "tried": len(seeds) + len(failed),
              "training": recipe(report["task"])}  # fmt: skip
    (out / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def train_once(data: Path, run: Path, policy: str, *flags: str) -> dict:
    """``train`` (made if absent); its wall time, peak memory and the train.json it wrote."""
    figures = run / "figures.json"
    if not figures.is_file():
        peak: dict = {}
        wall = cake("train", str(data), "--out", str(run), "--policy", policy, "--device",
                    "cpu", *flags, peak=peak)  # fmt: skip
        figures.write_text(json.dumps({"train_s": wall, **peak}))
    made = {**json.loads(figures.read_text()), **json.loads((run / "train.json").read_text())}
    spent(f"training {run}", made["train_s"])
    return {**made, "steps": made["recipe"]["steps"]}


def pixels(args) -> None:
    """A policy that sees, beside the state policy, from one recording with cameras."""
    rows = [
        ("mlp, state (poses)", "state", ["--inputs", "state"]),
        ("mlp, both cameras", "images", ["--inputs", "images"]),
        ("mlp, scene camera", "scene", ["--inputs", "images", "--cameras", "scene"]),
        ("mlp, wrist camera", "wrist", ["--inputs", "images", "--cameras", "wrist"]),
    ]
    for demos in args.pixels:
        for task in args.tasks:
            data = args.work / f"{task}_demos{demos}_cameras"
            if not (data / "meta" / "info.json").is_file():
                seconds = cake("record", str(LEARNING), "--name", task, "--out", str(data),
                               "--episodes", str(demos))  # fmt: skip
                print(f"recorded {demos} {task} demonstrations with cameras in "
                      f"{seconds / 60:.1f} min", flush=True)  # fmt: skip
            print(f"{task}, {demos} demonstrations with the task's cameras")
            for label, tag, flags in rows:
                if "--cameras" in flags and task not in args.views:
                    continue
                run = args.work / f"{task}_pixels{demos}_{tag}"
                made = train_once(data, run, "mlp", *flags)
                s = evaluate(task, str(run), run / "evaluation", args.episodes, args.eval_seed)
                batch = made["recipe"]["batch_size"]
                peak = f"{made['peak_mib']:.0f} MiB" if "peak_mib" in made else "-"
                print(f"{row(label, s, made)}  batch {batch}, peak {peak}", flush=True)


def compare(task: str, policy: str, args) -> list[str]:
    """BC, DART and DAgger rows of ``task`` at equal expert-labelled frames (its lines)."""
    steps = ["--steps", str(args.steps)] if args.steps else []
    length = f"steps{args.steps}" if args.steps else recipe_tag(task)
    start = demonstrations(task, args.start_demos, args.work)
    run = args.work / (
        f"{task}_{policy}_dagger{args.start_demos}x{args.rounds}x{args.per_round}"
        f"_beta{args.beta:g}_{length}"
    )
    flags = ["--dagger", str(args.rounds), "--episodes-per-round", str(args.per_round),
             "--beta", str(args.beta)]  # fmt: skip
    figures = train_once(start, run, policy, *steps, *flags)
    frames = figures["dagger"]["expert_labelled_frames"]
    dagger = f"{args.start_demos} demos + {args.rounds} x {args.per_round}, beta {args.beta:g}"
    runs, trainings = [], []
    for label, noise in (("BC", 0.0), ("DART", args.noise)):
        pool = recorded(task, args.pool, args.work, noise)
        tag = f"{task}_{label.lower()}{noise:g}_frames{frames}"
        data = args.work / f"{tag}_{recipe_tag(task)}_data"
        report = subset(pool, data, frames=frames)
        trained_run = args.work / f"{tag}_{policy}_{length}"
        extra = f"{report['episodes']} demos" + (f", noise {noise:g}" if noise else "")
        if report["frames"] < frames:
            extra += f" (all the pool has: --pool {args.pool} is short)"
        runs.append((label, trained_run, report["frames"], extra))
        trainings.append(functools.partial(train_once, data, trained_run, policy, *steps))
    made = at_once(args.jobs, trainings)  # BC and DART side by side
    runs = [(label, r, n, m, extra) for (label, r, n, extra), m in zip(runs, made, strict=True)]
    runs.append(("DAgger", run, frames, figures, dagger))
    lines = []
    for label, trained_run, labelled, made, extra in runs:
        s = evaluate(task, str(trained_run), trained_run / "evaluation", args.episodes,
                     args.eval_seed)  # fmt: skip
        lo, hi = wilson(s["success"], s["episodes"])
        lines.append(
            f"  {label + ', ' + policy:<14} {labelled:>7} frames  {s['success']:>3}/"
            f"{s['episodes']:<3} {s['rate']:>5.0%}  [{lo:4.0%}, {hi:4.0%}]  "
            f"train {made['train_s'] / 60:5.1f} min  {extra}"
        )
        lines.append(failures(s))
    return lines


def skills(args) -> None:
    """Rows of learned skills under the planner, and the classical layer beside each: per
    row, success, how the monitor's loop rescued episodes, how far each stack was set off
    the cube below, and the simulated time."""
    from dataclasses import replace

    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.learning.evaluation import evaluate as evaluate_here
    from cake_drake.scenario import SKILL_POLICY, load_scenario

    kept = ROOT / "models" / "policies" / "skills_joint_space"
    # Each checkpoint as trained (its chunk's first actions open loop, then a new chunk),
    # and the kept joint-space one also with its chunks ensembled (motion.skill_ensemble).
    checkpoints = ([("joint-space", kept, 0.0), ("joint-space, ensembled", kept, 0.01)]
                   if args.joint_space else [])  # fmt: skip
    for task in args.skill_tasks:
        for demos in args.skills:
            run, figures = trained(task, "mlp", demos, args.work)
            space = load_scenario(LEARNING, task.split("+")[0]).reference.action_space
            print(f"{task}: mlp on observation.skill answering {space}, {demos} demos, "
                  f"trained {figures['train_s'] / 60:.1f} min "
                  f"({figures['steps'] / figures['train_s']:.1f} steps/s)")  # fmt: skip
            checkpoints.append((f"{task.replace(':', '')}{demos}", run, 0.0))
    rows = [(task, None) for task in args.tasks] + [("blocks3", n) for n in args.sizes]
    for task, size in rows:
        name = f"{task}" if size is None else f"generated {size}"
        print(name)
        tag = task if size is None else f"generated{size}"
        for label, path, ensemble in [*checkpoints, ("classical", "", 0.0)]:
            out = args.work / f"skills_{label.replace(', ', '_')}_{tag}" / "summary.json"
            if not out.is_file():
                spec = replace(
                    spec_from_scenario(load_scenario(LEARNING, task)),
                    cameras=(),
                    policy=SKILL_POLICY,
                    options={"path": str(path), "device": "cpu", "ensemble": ensemble},
                )
                if size is not None:  # the budget scaled to each problem's plan
                    spec = replace(spec, blocks=(size, size), problem=None, max_steps=0)
                seeds = [args.eval_seed + k for k in range(args.episodes)]
                _, summary = evaluate_here(spec, seeds, len(os.sched_getaffinity(0)))
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_text(json.dumps(summary, indent=2))
            s = json.loads(out.read_text())
            m, places = s["monitor"], s.get("places") or {}
            offsets = (f"stacks {places['median_mm']:.1f}/{places['p95_mm']:.1f} mm"
                       if places.get("count") else "stacks -")  # fmt: skip
            print(
                f"{row(label, s)}  rescued {m['rescued']}/"
                f"{m['episodes_with_repeats_or_replans']}  {offsets}  "
                f"sim {s.get('mean_sim_s', float('nan')):.1f} s",
                flush=True,
            )
            why = {k: v for k, v in s["reasons"].items() if k != "goal reached"}
            for reason, count in sorted(why.items(), key=lambda kv: -kv[1])[:3]:
                print(f"      {count} x {reason[:110]}")


def failures(s: dict) -> str:
    """How a row's failed episodes ended: why, and the goal's facts most often missing at
    their end (the first failures' last pictures are the evaluation's failures.png)."""
    why = {k: v for k, v in s["reasons"].items() if k != "goal reached"}
    if not why:
        return "    failures: none"
    text = "; ".join(f"{v}x {k}" for k, v in sorted(why.items(), key=lambda kv: -kv[1]))
    missing = list(s.get("missing_at_end", {}).items())[:4]
    if missing:
        text += " · missing at the end: " + ", ".join(f"{f} {n}" for f, n in missing)
    return f"    failures: {text}"


def row(name: str, s: dict, train: dict | None = None) -> str:
    lo, hi = wilson(s["success"], s["episodes"])
    per_min = 60.0 / s["mean_wall_s"]  # episodes a minute on one worker (one core)
    trained_text = (
        f"{train['train_s'] / 60:6.1f} min {train['steps'] / train['train_s']:5.1f}/s"
        if train
        else f"{'-':>17}"
    )
    return (
        f"  {name:<24} {s['success']:>3}/{s['episodes']:<3} {s['rate']:>5.0%}  "
        f"[{lo:4.0%}, {hi:4.0%}]  {trained_text}  {per_min:5.1f} ep/min"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tasks", nargs="+", default=["stack2", "tower3", "tower5", "blocks3"])
    p.add_argument("--demos", type=int, nargs="+", default=[100, 300])
    p.add_argument("--policies", nargs="*", default=["act", "diffusion"])
    p.add_argument("--episodes", type=int, default=50, help="held-out episodes per row")
    p.add_argument("--eval-seed", type=int, default=100_000, help="the first held-out seed")
    p.add_argument("--work", type=Path, default=ROOT / "outputs" / "learning_benchmark")
    p.add_argument("--compare", action="store_true", help="BC, DART, DAgger at equal labels")
    p.add_argument("--all", action="store_true", help="the whole table of docs/learning.md")
    p.add_argument(
        "--jobs", type=int, default=trainings_at_once(),
        help="trainings side by side (default: 2 on two cores, where one uses one core)",
    )  # fmt: skip
    p.add_argument("--start-demos", type=int, default=20, help="DAgger's demonstrations")
    p.add_argument("--rounds", type=int, default=4, help="DAgger's rounds")
    p.add_argument("--per-round", type=int, default=20, help="DAgger's rollouts a round")
    p.add_argument("--beta", type=float, default=0.3, help="DAgger: P(the expert's action)")
    p.add_argument("--noise", type=float, default=0.005, help="DART's noise (rad a joint)")
    p.add_argument("--pool", type=int, default=300, help="episodes recorded for BC and DART")
    p.add_argument("--steps", type=int, help="training steps (default: the task's recipe)")
    p.add_argument(
        "--skills",
        type=int,
        nargs="*",
        default=[],
        metavar="DEMOS",
        help="learned skills under the planner from DEMOS demonstrations",
    )
    p.add_argument("--sizes", type=int, nargs="*", default=[], help="generated sizes (--skills)")
    p.add_argument(
        "--skill-tasks",
        nargs="+",
        default=["skills"],
        help="--skills: the recording tasks trained (skills: joint targets; skills_hand: "
        "moves of the hand; skills+skills_tall:300: with 300 tall-tower ones)",
    )
    p.add_argument(
        "--joint-space",
        action="store_true",
        help="--skills: models/policies/skills_joint_space too",
    )
    p.add_argument(
        "--pixels",
        type=int,
        nargs="*",
        default=[],
        metavar="DEMOS",
        help="a policy that sees, from DEMOS demonstrations with cameras",
    )
    p.add_argument("--views", nargs="*", default=[], help="--pixels: one camera at a time")
    args = p.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    print(machine())
    print(f"held-out seeds {args.eval_seed}..{args.eval_seed + args.episodes - 1}")
    if args.skills or args.joint_space:
        skills(args)
        return
    if args.pixels:
        pixels(args)
        return
    if args.all:
        everything(args)
        return
    if args.compare:
        comparison(args, args.tasks, args.policies)
        return
    table(args, args.tasks, args.policies, args.demos)


def comparison(args, tasks, policies) -> None:
    print(f"  {'method':<14} {'labelled':>13}  {'success':>7} {'rate':>5}  "
          f"{'95 % interval':<13}")  # fmt: skip
    for task in tasks:  # the pools, before the comparisons share them
        recorded(task, args.start_demos, args.work)
    pairs = [(task, policy) for task in tasks for policy in policies]
    made = at_once(args.jobs, [functools.partial(compare, task, policy, args)
                               for task, policy in pairs])  # fmt: skip
    for k, ((task, _), lines) in enumerate(zip(pairs, made, strict=True)):
        if k == 0 or pairs[k - 1][0] != task:
            print(task)
        print("\n".join(lines), flush=True)


def table(args, tasks, policies, demos_list, baselines: bool = True) -> None:
    print(f"  {'policy':<24} {'success':>7} {'rate':>6}  {'95 % interval':<13} "
          f"{'training':>17}  {'evaluation':>10}")  # fmt: skip
    for task in tasks:
        print(task)
        for name, policy in (("expert", None), ("random", RANDOM)) if baselines else ():
            from cake_drake.scenario import load_scenario

            spec = policy or load_scenario(LEARNING, task).reference.factory
            s = evaluate(task, spec, args.work / f"{task}_{name}", args.episodes, args.eval_seed)
            print(row(name, s), flush=True)
        rows = [(policy, demos) for policy in policies for demos in demos_list]
        for demos in sorted(set(demos_list)):  # the datasets, before trainings share them
            demonstrations(task, demos, args.work)
        made = at_once(args.jobs, [functools.partial(trained, task, policy, demos, args.work)
                                   for policy, demos in rows])  # fmt: skip
        for (policy, demos), (run, figures) in zip(rows, made, strict=True):
            s = evaluate(task, str(run), run / "evaluation", args.episodes, args.eval_seed)
            print(row(f"{policy}, {demos} demos (state)", s, figures), flush=True)
            print(profile(figures, s), flush=True)
            print(failures(s), flush=True)


def trainings_at_once() -> int:
    """How many trainings the cores take side by side: ``train`` gives the network every
    core but one, so on two cores a training leaves one idle for another."""
    cores = len(os.sched_getaffinity(0))
    return max(1, cores // max(1, cores - 1))


def at_once(jobs: int, calls: list) -> list:
    """Each of ``calls``' answers, in order, ``jobs`` of them running at a time (each runs
    its command in a process of its own)."""
    from concurrent.futures import ThreadPoolExecutor

    if jobs <= 1 or len(calls) <= 1:
        return [call() for call in calls]
    with ThreadPoolExecutor(jobs) as pool:
        return list(pool.map(lambda call: call(), calls))


def everything(args) -> None:
    """The whole table of docs/learning.md: every task x the mlp recipe from 100, 300 and
    1,000 demonstrations; stack2 x ACT and Diffusion Policy from 300; BC, DART and DAgger
    on tower5 and blocks3; then the total time."""
    t0 = time.perf_counter()
    table(args, ["stack2", "tower3", "tower5", "blocks3"], ["mlp"], [100, 300, 1000])
    table(args, ["stack2"], ["act", "diffusion"], [300], baselines=False)
    comparison(args, ["tower5", "blocks3"], ["mlp"])
    print(f"the whole table: {(time.perf_counter() - t0) / 60:.0f} min (cached rows not redone)")
    print(f"from nothing: {sum(SPENT.values()) / 60:.0f} min, every recording, training and "
          "evaluation it used, as long as each took when it was made", flush=True)  # fmt: skip
    for what in sorted(UNKNOWN):
        print(f"  (and {what}: made before its time was kept)")


if __name__ == "__main__":
    main()
