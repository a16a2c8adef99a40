"""``evaluate``: a policy's success rate on seeded problems, with its figures.

A policy factory, a trained checkpoint or learned skills (their folder says which) runs
through :func:`cake_drake.learning.evaluation.evaluate`; this module parses the flags,
writes the table and summary, and draws ``success.png`` and ``failures.png``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from cake_drake import artifacts
from cake_drake.commands.common import (
    CliParser,
    add_ray_flag,
    add_set_flag,
    ray_engine,
    worker_count,
)
from cake_drake.errors import EXIT_OK, InputError

EVALUATE_DOC = """Evaluate a policy on seeded generated problems: success rate with a 95 %
Wilson interval, per problem size, mean steps and time, and why episodes ended.

POLICY is module:attribute of a policy factory (the policy slot's protocol:
reset(task, seed), act(observation)), or a folder written by python -m cake_drake.train
(any LeRobot checkpoint folder), run on --device. --suite is a scenario giving the
problems, action space and cameras (as record reads it); --blocks LO HI draws each
problem's size; --seed sets the first episode's seed (default: the scenario's), so
held-out seeds can be chosen.

Writes to --out (default outputs/evaluate/): results.parquet and results.csv (one row
per episode: its verdict, why it ended and the goal's facts still missing at its end),
summary.json (with how often each goal fact was missing at a failure's end) and
success.png; --frames K adds failures.png, the last picture of the first K failed
episodes, to see where a policy goes wrong. Exit codes: 0 done; 2 bad input; 3 the policy failed;
4 the outputs could not be written.
"""


def evaluate_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="python -m cake_drake.evaluate",
        description=EVALUATE_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("policy", help="module:attribute of the policy's factory, or a checkpoint")
    p.add_argument("--suite", type=Path, required=True, help="a scenario file")
    p.add_argument("--name", help="the scenario's name in the suite file")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--seed", type=int, help="the first episode's seed (default: the suite's)")
    p.add_argument("--device", default="auto", help="a checkpoint's device: auto | cpu | cuda")
    p.add_argument("--blocks", type=int, nargs=2, metavar=("LO", "HI"), help="problem sizes")
    p.add_argument("--workers", type=int, help="worker processes (default: cores)")
    p.add_argument(
        "--frames", type=int, default=0, metavar="K",
        help="failures.png: the last picture of the first K failed episodes",
    )  # fmt: skip
    add_ray_flag(p)
    p.add_argument("--out", type=Path, default=Path("outputs") / "evaluate")
    add_set_flag(p, "the suite's scenario")
    return p


def main_evaluate(argv: list[str] | None = None) -> int:
    from dataclasses import replace

    from cake_drake.learning.data.recording import spec_from_scenario
    from cake_drake.learning.evaluation import evaluate
    from cake_drake.outputs.files import OutputDir
    from cake_drake.plugins import is_plugin
    from cake_drake.scenario import CHECKPOINT_POLICY, SKILL_POLICY, load_scenario

    args = evaluate_parser().parse_args(argv)
    workers = worker_count(args.workers)
    if not 1 <= args.episodes <= 100_000:
        raise InputError(f"--episodes {args.episodes}: from 1 to 100000")
    if not 0 <= args.frames <= 64:
        raise InputError(f"--frames {args.frames}: from 0 (no picture) to 64 failed episodes")
    scenario = load_scenario(args.suite, args.name, args.set)
    checkpoint = Path(args.policy).is_dir() or not is_plugin(args.policy)
    spec = replace(spec_from_scenario(scenario, args.policy), cameras=())
    # The folder's kind, decided once (cake_drake.artifacts): what evaluate runs is a
    # whole-task policy (imitation or RL) or learned skills, never a planner or residual.
    kind = (
        artifacts.require(
            args.policy, "policy", "rl", *artifacts.SKILL_KINDS, role="what evaluate runs"
        )  # fmt: skip
        if checkpoint
        else None
    )
    skills = kind is not None and kind.name in artifacts.SKILL_KINDS
    if skills and args.frames:
        raise InputError(
            f"--frames {args.frames}: learned skills run whole runs under the planner; "
            "python -m cake_drake.run with the skill checkpoint draws one's end"
        )
    if skills:  # learned skills: the demonstrator's place under the planner
        from cake_drake.learning.skills.checkpoints import check_folder

        check_folder(Path(args.policy), args.device)
        options = {"path": str(Path(args.policy).resolve()), "device": args.device}
        spec = replace(spec, policy=SKILL_POLICY, options=options)
    elif checkpoint:  # a trained policy: the learned layer's adapter runs it
        from cake_drake.learning.policies.checkpoint import check_folder, sees

        check_folder(Path(args.policy), spec.control_mode, args.device, scenario.cameras)
        options = {**spec.options, "path": str(Path(args.policy).resolve()), "device": args.device}
        spec = replace(spec, policy=CHECKPOINT_POLICY, options=options)
        if sees(Path(args.policy)):
            spec = replace(spec, cameras=spec_from_scenario(scenario).cameras)
    first = scenario.seed if args.seed is None else args.seed
    if not -(2**31) <= first <= 2**31 - 1:
        raise InputError(f"--seed {first}: from -2147483648 to 2147483647")
    if args.blocks:
        lo, hi = args.blocks
        if not 1 <= lo <= hi <= 12:
            raise InputError(f"--blocks {lo} {hi}: from 1 to 12 cubes, LO <= HI")
        spec = replace(spec, blocks=(lo, hi), problem=None)
    names = ("results.parquet", "results.csv", "summary.json", "success.png", "failures.png")
    with OutputDir(args.out, "evaluate", names, [args.suite]) as out:
        from cake_drake.plugins import resolve

        if not checkpoint:
            resolve(args.policy, {}, "policy")  # refused before any episode
        seeds = [first + k for k in range(args.episodes)]
        rows, summary = evaluate(spec, seeds, workers, ray_engine(args.ray, workers), args.frames)
        from cake_drake.sweeps.table import write_table

        failed = [r.pop("final") for r in rows if "final" in r]
        if failed:
            _figure(_failures_picture, [r for r in rows if not r["success"]], failed,
                    out.path("failures.png"))  # fmt: skip
        keys = ["seed", "blocks", "success", "steps", "wall_s", "reason", "task"]
        keys += ["repeats", "replans", "sim_s"] if skills else ["missing"]
        for r in rows if not skills else ():  # a column of text: "(on a b) (on b c)"
            r["missing"] = " ".join(r["missing"])
        out.path("results.parquet"), out.path("results.csv")  # declared, written below
        write_table(sorted(rows, key=lambda r: r["seed"]), out.staging, keys, exact=True)
        out.write_json("summary.json", summary)
        _figure(success_plot, summary, out.path("success.png"))
        out.commit()
    lo, hi = summary["ci95"]
    print(
        f"{args.policy}: {summary['success']}/{summary['episodes']} episodes reached the goal "
        f"({summary['rate']:.0%}, 95 % interval {lo:.0%} to {hi:.0%}); mean "
        f"{summary['mean_steps']:.0f} steps{_places_text(summary)}; outputs in {args.out}/"
    )
    return EXIT_OK


def _figure(draw: Callable[..., None], *args) -> None:
    """Draw a figure; where drawing fails, say so in one line on stderr and go on: a
    picture must never cost the user the numbers written beside it."""
    try:
        draw(*args)
    except Exception as e:  # noqa: BLE001 - any failure of the drawing library
        name = Path(args[-1]).name
        print(f"warning: {name} not drawn ({type(e).__name__}: {e}); the numbers are "
              "written", file=sys.stderr)  # fmt: skip


def _places_text(summary: dict) -> str:
    """How far the skills set stacked cubes off the one below (under the planner)."""
    places = summary.get("places") or {}
    if not places.get("count"):
        return ""
    return (
        f"; {places['count']} stacks set {places['median_mm']:.1f} mm off the cube below "
        f"(median; 95th percentile {places['p95_mm']:.1f} mm)"
    )


def _failures_picture(rows: list[dict], frames: list, path: Path) -> None:
    """The last picture of each of the first failed episodes (``rows``, in seed order),
    titled with its seed, why it ended and the goal's facts still missing."""
    import textwrap

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = min(4, len(frames))
    lines = (len(frames) + columns - 1) // columns
    fig, axes = plt.subplots(lines, columns, figsize=(4 * columns, 3.6 * lines), dpi=80,
                             squeeze=False)  # fmt: skip
    for ax in axes.flat:
        ax.axis("off")
    for ax, row, frame in zip(axes.flat, rows, frames, strict=False):
        ax.imshow(frame)
        missing = " ".join(row["missing"]) or "nothing"
        said = (f"seed {row['seed']}: {row['reason']}", f"missing {missing}")
        ax.set_title("\n".join(line for s in said for line in textwrap.wrap(s, 48)), fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def success_plot(summary: dict, path: Path) -> None:
    """`evaluate`'s success.png: the success rate per problem size with its 95 % interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = summary["per_size"]
    xs = [int(n) for n in sizes]
    rate = [sizes[n]["success"] / sizes[n]["episodes"] for n in sizes]
    lo = [r - sizes[n]["ci95"][0] for r, n in zip(rate, sizes, strict=True)]
    hi = [sizes[n]["ci95"][1] - r for r, n in zip(rate, sizes, strict=True)]
    fig, ax = plt.subplots(figsize=(6, 3.5), dpi=100)
    ax.errorbar(xs, rate, yerr=[lo, hi], fmt="o-", capsize=4)
    ax.set_ylim(-0.05, 1.05)
    ax.set_xticks(xs)
    ax.set_xlabel("blocks in the problem")
    ax.set_ylabel("success rate (95 % interval)")
    ax.set_title(f"{summary['policy']} ({summary['control_mode']})", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
