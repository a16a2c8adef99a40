"""The cake from the cameras: the perception layer's table (docs/perception.md).

Each row runs whole episodes (planning, the execution monitor, the simulation, the
verdict from the simulator's truth) three ways: ``truth`` (the simulator's own poses),
``depth`` (the cameras, noise-free depth) and ``depth+noise`` (the axial noise model),
on the same seeds, and prints success with its 95 % Wilson interval, the final stacks'
offsets off the cube below (the truth's, median / p95 mm), the estimator's error over every estimate
(position median / p95 mm, yaw p95 degrees) and its frames, the simulated and the
wall time of the simulation.

Rows:

- ``problem_5``: the exercise's problem, its towers placed at random per seed;
- ``tall10``: generated ten-cube problems of few, tall towers;
- ``generated8`` / ``tall8``: generated eight-cube problems, with ``--skills`` the
  learned skills (``models/policies/skills``) as the geometric layer.

Seeds: the development seeds, 200000 and up (with 300000-300049, whose tall towers
showed the estimator tilting resting cubes, and 400000-400049, whose first seed showed
ICP leaving a side-only cube), are where failures were read and the estimator's
tolerances set; the table is reported on the test seeds, 500000 and up (``--episodes``
of them), never read while tuning. ``--dev`` runs the development seeds.

The ``learned`` and ``learned+noise`` columns read the learned eyes (``--eyes``: the
shipped ``learned``, or ``learned@DIR``), trained on frames of seeds 600000 and up.
``--frames`` sets them beside the classical fit on the same sightings: runs of the
classical estimator keep every cube's points, the network answers from the very same
points, and both are measured against the truth (noise-free, with depth noise, and with
every camera moved 2 cm and turned 2 degrees, the estimator told), with the network's
time for each frame's cubes. ``--figure PNG`` draws one frame with both outlines.

    python benchmarks/perception.py --episodes 50 --rows problem_5 tall10
    python benchmarks/perception.py --episodes 50 --rows problem_5 generated8 tall8 --skills
    python benchmarks/perception.py --episodes 3 --rows problem_5 --workers 1   # a quick look
    python benchmarks/perception.py --frames --episodes 10 --rows problem_5 tall10
    python benchmarks/perception.py --episodes 50 --rows problem_5 --columns learned learned+noise
    python benchmarks/perception.py --episodes 50 --rows learned_cake --skills --columns learned
        --json cake.json            # then, stopped early, the same with --resume to go on
    python benchmarks/perception.py --figure docs/images/perception_learned.png --episodes 1
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from pathlib import Path

import numpy as np
from cake import why  # a failure's kind, as the cake's table says it
from machine import machine
from skills import scenario_for as skills_scenario  # benchmarks/skills.py

SKILLS = "package://cake_drake/policies/skills"
DEV_SEED, TEST_SEED = 200000, 500000
COLUMNS = ("truth", "depth", "depth+noise", "learned", "learned+noise")
#: The learned eyes the ``learned`` columns read (``--eyes DIR``: another's).
EYES = "learned"


def scenario_for(row: str, column: str, seed: int, skills: str, eyes: str = EYES):
    """The episode's scenario: ``row``'s problem and world (the skills table's), ``column``'s
    estimator."""
    s = skills_scenario(row, skills, seed)
    s.perception.estimator = column.split("+")[0]
    if s.perception.estimator == "learned":
        s.perception.estimator = eyes
    s.perception.noise.model = "axial" if column.endswith("noise") else "off"
    return s


def moved(cameras, seed: int, metres: float = 0.02, degrees: float = 2.0):
    """``cameras``, each moved ``metres`` and turned ``degrees`` in directions drawn from
    ``seed`` (the estimator told where they are)."""
    rng = np.random.default_rng(seed)
    for c in cameras:
        step = rng.normal(size=3)
        c.xyz = list(np.add(c.xyz, metres * step / np.linalg.norm(step)))
        look = np.subtract(c.target, c.xyz)
        side = np.cross(look, rng.normal(size=3))
        side *= np.linalg.norm(look) * np.tan(np.radians(degrees)) / np.linalg.norm(side)
        c.target = list(np.add(c.target, side))
    return cameras


def same_frames(job) -> dict:
    """One run of the classical estimator (in a worker), and on every sighting of it the
    learned eyes' answer from the same points: both errors against the truth, and the
    network's time for each frame's cubes."""
    row, noise, seed, eyes, shift = job
    from cake_drake.perception.learned import checkpoint_of, load
    from cake_drake.perception.report import yaw_error_deg
    from cake_drake.perception.settings import default_cameras
    from cake_drake.pipeline import run

    s = scenario_for(row, "depth+noise" if noise else "depth", seed, "")
    s.perception.keep_points = True
    if shift:
        s.perception.cameras = moved(default_cameras(), seed)
    result = run(s, write=False)
    rec = result.execution.perception
    net = load(checkpoint_of(eyes))
    classical = {(round(r["t"], 6), r["cube"]): r for r in rec["rows"] if r["seen"]}
    out = {"row": row, "seed": seed, "classical_mm": [], "classical_yaw": [], "learned_mm": [],
           "learned_yaw": [], "frame_ms": [], "success": result.success}  # fmt: skip
    frames: dict[float, dict] = {}
    for t, name, P, rays, *_ in rec["samples"]:
        frames.setdefault(t, {})[name] = (P, rays, None)
    answers = {}
    for t, cubes in frames.items():  # as a run asks: every cube of a frame at once
        t0 = time.perf_counter()
        answers.update({(t, n): fit for n, fit in net.fit_all(cubes).items()})
        out["frame_ms"].append((time.perf_counter() - t0) * 1000)
    for t, name, _, _, p, R in rec["samples"]:
        mine = classical.get((round(t, 6), name))
        fit = answers.get((t, name))
        if mine is None or fit is None:
            continue
        out["classical_mm"].append(mine["position_mm"])
        out["classical_yaw"].append(mine["yaw_deg"])
        out["learned_mm"].append(float(np.linalg.norm(fit.X_WB.translation() - p)) * 1000)
        out["learned_yaw"].append(yaw_error_deg(fit.X_WB.rotation().matrix(), R))
    return out


def frames_table(args, seeds) -> None:
    """The learned eyes beside the classical fit on the same sightings."""
    from cake_drake.learning.parallel import imap

    rows = [("noise-free", False, False), ("depth noise", True, False),
            ("cameras moved 2 cm, 2 deg", False, True)]  # fmt: skip
    print("| frames | sightings | classical mm (median / p95) | yaw p95 | learned mm "
          "(median / p95) | yaw p95 | network ms a frame (median / p95) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for label, noise, shift in rows:
        jobs = [(r, noise, s, args.eyes, shift) for r in args.rows for s in seeds]
        done = list(imap(same_frames, jobs, args.workers))
        get = lambda k, done=done: [x for d in done for x in d[k]]  # noqa: E731
        print(f"| {', '.join(args.rows)}, {label} | {len(get('learned_mm'))} "
              f"| {_pair(get('classical_mm'))} | {np.percentile(get('classical_yaw'), 95):.2f} "
              f"| {_pair(get('learned_mm'))} | {np.percentile(get('learned_yaw'), 95):.2f} "
              f"| {_pair(get('frame_ms'), '{:.1f}')} |", flush=True)  # fmt: skip


def figure(path: Path, seed: int, eyes: str) -> None:
    """One frame of problem_5 from the front camera, each cube outlined as the classical
    fit and as the learned eyes estimate it from the same points, and both estimators'
    errors over the run's sightings."""
    from matplotlib.figure import Figure

    from cake_drake.outputs.perception import outline
    from cake_drake.perception.learned import checkpoint_of, load
    from cake_drake.pipeline import run

    s = scenario_for("problem_5", "depth+noise", seed, "")
    s.perception.keep_points = True
    rec = run(s, write=False).execution.perception
    net = load(checkpoint_of(eyes))
    last = max(t for t, *_ in rec["samples"])
    learned = {n: net.fit(P, r, rec["estimates"].get(n))
               for t, n, P, r, *_ in rec["samples"] if t == last}  # fmt: skip
    fig = Figure(figsize=(11, 4.4), dpi=110)
    ax, ax_err = fig.add_axes((0.01, 0.06, 0.52, 0.84)), fig.add_axes((0.61, 0.14, 0.37, 0.74))
    image, camera = rec["image"], rec["camera"]
    ax.imshow(image, extent=(0, image.shape[1], image.shape[0], 0))
    drawn = []
    for name, X in rec["estimates"].items():
        for edge in outline(X, camera):
            ax.plot(edge[:, 0], edge[:, 1], color="white", linewidth=1.8)
            drawn.append(edge)
        fit = learned.get(name)
        for edge in outline(fit.X_WB, camera) if fit is not None else []:
            ax.plot(edge[:, 0], edge[:, 1], color="black", linewidth=1.0, linestyle=(0, (3, 2)))
    pts = np.vstack(drawn)
    (cx, cy) = (pts.min(axis=0) + pts.max(axis=0)) / 2
    half_w, half_h = np.ptp(pts[:, 0]) / 2 + 10, np.ptp(pts[:, 1]) / 2 + 10
    half_w, half_h = max(half_w, half_h * 4 / 3), max(half_h, half_w * 3 / 4)
    ax.set_xlim(cx - half_w, cx + half_w)
    ax.set_ylim(cy + half_h, cy - half_h)
    ax.axis("off")
    ax.set_title(f"problem_5 (seed {seed}, depth noise), camera {camera.name}, the last "
                 "frame:\nsolid white, the classical fit (ICP); dashed black, the learned eyes",
                 fontsize=9)  # fmt: skip
    classical = {(round(r["t"], 6), r["cube"]): r["position_mm"] for r in rec["rows"] if r["seen"]}
    errs = {"classical": [], "learned": []}
    for t, name, P, rays, p, _ in rec["samples"]:
        fit = net.fit(P, rays, None)
        if fit is not None and (round(t, 6), name) in classical:
            errs["classical"].append(classical[(round(t, 6), name)])
            errs["learned"].append(float(np.linalg.norm(fit.X_WB.translation() - p)) * 1000)
    bins = np.linspace(0, max(4.0, np.percentile(errs["learned"], 99)), 40)
    for label, colour in (("classical", "#9c7434"), ("learned", "#355f9c")):
        e = errs[label]
        ax_err.hist(e, bins=bins, histtype="step", linewidth=1.6, color=colour,
                    label=f"{label}: median {np.median(e):.2f}, p95 "
                          f"{np.percentile(e, 95):.2f} mm")  # fmt: skip
    ax_err.set_xlabel("position error of a sighting (mm)")
    ax_err.set_ylabel("sightings")
    ax_err.legend(fontsize=8)
    ax_err.grid(alpha=0.3)
    ax_err.set_title(f"the same {len(errs['learned'])} sightings of the run, both estimators",
                     fontsize=9)  # fmt: skip
    fig.savefig(path)
    print(f"{path}: written")


def episode(job) -> dict:
    """One whole run (in a worker): its row of the table."""
    row, column, seed, skills, eyes = job
    from cake_drake.errors import CakeDrakeError
    from cake_drake.pipeline import run

    t0 = time.perf_counter()
    out = {"row": row, "column": column, "seed": seed, "success": False, "places_mm": [],
           "position_mm": [], "yaw_deg": [], "frames": 0, "sim_s": 0.0,
           "sim_wall_s": 0.0}  # fmt: skip
    try:
        result = run(scenario_for(row, column, seed, skills, eyes), write=False)
        e = result.execution
        out.update(success=result.success, message=result.message, sim_s=e.sim_s,
                   sim_wall_s=e.wall_s,
                   places_mm=[v * 1000 for v in e.offsets.values()])  # fmt: skip
        if e.perception:
            out["position_mm"] = [r["position_mm"] for r in e.perception["rows"]]
            out["yaw_deg"] = [r["yaw_deg"] for r in e.perception["rows"]]
            out["frames"] = e.perception["summary"]["frames"]
    except CakeDrakeError as err:
        out["message"] = str(err)
    out["wall_s"] = time.perf_counter() - t0
    return out


def _pair(values, fmt="{:.2f}") -> str:
    if not values:
        return "-"
    return f"{fmt.format(np.median(values))} / {fmt.format(np.percentile(values, 95))}"


def main(argv=None) -> int:
    from cake_drake.learning.evaluation import wilson
    from cake_drake.learning.parallel import imap

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=50, help="episodes a row (default 50)")
    ap.add_argument("--rows", nargs="+", default=["problem_5", "tall10"])
    ap.add_argument("--columns", nargs="+", default=list(COLUMNS[:3]), choices=COLUMNS)
    ap.add_argument("--skills", action="store_true", help="the learned skills as geometry")
    ap.add_argument("--dev", action="store_true", help="the development seeds instead")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, help="also write every episode's row here")
    ap.add_argument("--resume", action="store_true", help="run only what --json lacks")
    ap.add_argument("--eyes", default=EYES, help="the learned columns' estimator (learned@DIR)")
    ap.add_argument("--figure", type=Path, help="draw one frame with both estimators here")
    ap.add_argument(
        "--frames",
        action="store_true",
        help="the learned eyes beside the classical fit on the same sightings",
    )
    args = ap.parse_args(argv)
    print(machine())
    first = DEV_SEED if args.dev else TEST_SEED
    seeds = range(first, first + args.episodes)
    skills = SKILLS if args.skills else ""
    if args.figure:
        figure(args.figure, seeds[0], args.eyes)
        return 0
    if args.frames:
        print(f"\n{args.episodes} runs a row ({'development' if args.dev else 'test'} seeds "
              f"{seeds[0]}-{seeds[-1]}), eyes {args.eyes}\n")  # fmt: skip
        frames_table(args, seeds)
        return 0
    jobs = [(row, col, s, skills, args.eyes) for row in args.rows for col in args.columns
            for s in seeds]  # fmt: skip
    t0 = time.perf_counter()
    done = []
    if args.resume:
        if not (args.json and args.json.is_file()):
            ap.error("--resume reads the episodes of --json FILE: give an existing file")
        done = json.loads(args.json.read_text())
        kept = {(d["row"], d["column"], d["seed"]) for d in done}
        jobs = [j for j in jobs if j[:3] not in kept]
        print(f"{args.json}: {len(done)} episodes kept, {len(jobs)} to run", flush=True)
    for d in imap(episode, jobs, args.workers):  # kept as each finishes: a long table stopped
        done.append(d)  # early still says what it measured
        print(
            f"{len(done)}: {d['row']} {d['column']} seed {d['seed']}: "
            f"{'built' if d['success'] else d.get('message', 'failed')}",
            flush=True,
        )
        if args.json:
            args.json.write_text(json.dumps(done, indent=1) + "\n")
    kind = "development" if args.dev else "test"
    layer = "learned skills" if skills else "classical"
    minutes = (time.perf_counter() - t0) / 60
    print(f"\n{args.episodes} episodes a row ({kind} seeds {seeds[0]}-{seeds[-1]}), geometric "
          f"layer {layer}, {minutes:.1f} min on {args.workers} workers (this piece)\n")  # fmt: skip
    print("| row | perception | success | 95 % interval | stacks mm (median / p95) | "
          "error mm (median / p95) | yaw p95 deg | frames | sim s | sim wall s "
          "| failures |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for row in args.rows:
        for col in args.columns:
            mine = [d for d in done if d["row"] == row and d["column"] == col
                    and d["seed"] in seeds]  # fmt: skip
            wins = sum(d["success"] for d in mine)
            lo, hi = wilson(wins, len(mine))
            places = [p for d in mine for p in d["places_mm"]]
            err = [x for d in mine for x in d["position_mm"]]
            yaw = [x for d in mine for x in d["yaw_deg"]]
            yaw95 = f"{np.percentile(yaw, 95):.2f}" if yaw else "-"
            frames = np.mean([d["frames"] for d in mine]) if err else 0
            sim = np.mean([d["sim_s"] for d in mine if d["success"]] or [float("nan")])
            wall = np.mean([d["sim_wall_s"] for d in mine if d["success"]] or [float("nan")])
            fails = Counter(why(d.get("message", "")) for d in mine if not d["success"])
            said = "; ".join(f"{n}× {w}" for w, n in fails.most_common(2)) or "-"
            print(f"| {row} | {col} | {wins}/{len(mine)} | {100 * lo:.0f}-{100 * hi:.0f} % "
                  f"| {_pair(places, '{:.1f}')} | {_pair(err)} | {yaw95} | {frames:.0f} "
                  f"| {sim:.1f} | {wall:.2f} | {said} |", flush=True)  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(done, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
