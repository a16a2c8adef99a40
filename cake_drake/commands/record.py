"""``record``: demonstrations as a LeRobot dataset, or a dataset's actions replayed.

The recording is the library's (:mod:`cake_drake.learning.data.recording`); this module parses
its flags.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cake_drake.commands.common import (
    CliParser,
    add_ray_flag,
    add_set_flag,
    ray_engine,
    worker_count,
)
from cake_drake.errors import EXIT_OK, InputError

RECORD_DOC = """Record demonstrations as a LeRobot dataset (v3.0), or check one by replaying it.

SPEC is a scenario: its problem (task.generate: that many blocks, a new problem per
seed; task.problem: that one, its cubes placed per seed by world.placement), its cameras
(the scene and wrist cameras when it names none; --no-cameras records none, which state
policies do not need) and, with reference: !Policy, the action space, rate and the
demonstrator. The demonstrator is the classical cake as a policy unless --policy or the
scenario names another. Seeds are the scenario's seed, +1, +2, ... Every frame holds
observation.state, observation.environment_state (the cubes' poses and the goal as
numbers) and the action; the report keeps the task's training recipe for train.

Each successful episode becomes one episode of the dataset in --out (meta/, data/,
videos/, lerobot's own writer); report.json lists what was recorded and why the other
episodes failed. Episodes run on a local pool (--workers N) or on Ray (--ray: a local
instance; --ray ADDRESS: a cluster); this process keeps each as it finishes, in
--out/episodes/: an interrupted recording keeps them, and --resume records only the rest.

--noise SIGMA records noise-injected demonstrations (DART): the executed action is the
demonstrator's plus Gaussian noise drawn from the episode's seed (the same seed, the same
noise), the recorded action the demonstrator's own. Units: joint_position, SIGMA rad on
each of the seven joints (at most 0.1); ee_delta, SIGMA m on dx, dy, dz and 5 SIGMA rad
on the rotations (their bounds' ratio), SIGMA at most 0.05 (a step's bound); the gripper
is never noised; joint_chunk is not recorded. Success is measured from the poses as ever:
only episodes that reach the goal are kept. The noise is in report.json.

--starts FILE records a start pool for a skill residual's task (training.rl with a base
that never sees the arm, as skills_rl): --episodes starts, each the Diagram's whole state
where the base skill began a place in a run of the task's problems (seeds from the
scenario's seed on), one JSON file written whole; training.rl.starts: FILE then starts
CakeDrake/Skill-v0's episodes there, nothing replayed. FILE must not exist yet.

--frames --out DIR records the learned eyes' data instead: --episodes runs of the classical
cake from the cameras (default 10; seeds from %(seed)d, or --set seed=S), each of a scene
drawn from its seed (a generated problem of 3 to 10 cubes, half of them tall towers, the
tasks' placement jitter, depth noise on half the runs, the cameras moved up to 1 cm); every
cube seen in every frame becomes a sighting: its depth points, their rays and its true
pose. DIR gets frames.json and frames.npz (docs/perception.md); train on it with python -m
cake_drake.train DIR --perception --out NET. No SPEC: the scenes are the recording's own.

--replay DATASET feeds every episode's actions (a noisy recording's executed ones), open
loop, through the same environment from the same seed and reports how many build the
goal again.

Needs lerobot: pip install 'cake_drake[lerobot]'. Exit codes: 0 done; 2 bad input (no
lerobot, a folder holding another recording without --resume, --resume with another
action space, rate, cameras, task or noise, an action space that cannot be recorded,
--noise negative, not a number or above its bound, a dataset missing a file; with
--starts, a FILE that exists or a task that is no skill residual's); 3 a policy plug-in
failed, or the lead skill gave most runs up; 4 the dataset or the pool could not be
written; 130 interrupted (finished episodes are kept).
"""


def record_parser() -> argparse.ArgumentParser:
    from cake_drake.learning.data.frames import FRAMES_SEED

    p = CliParser(
        prog="python -m cake_drake.record",
        description=RECORD_DOC % {"seed": FRAMES_SEED},
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("spec", type=Path, nargs="?", help="a scenario file")
    p.add_argument("--name", help="the scenario's name in SPEC, when it holds several")
    p.add_argument("--out", type=Path, help="the dataset's folder")
    p.add_argument("--episodes", type=int, default=10, help="episodes to try (default 10)")
    p.add_argument("--policy", help="the demonstrator: module:attribute of a policy factory")
    p.add_argument(
        "--no-cameras",
        action="store_true",
        help="record no images: joints, environment state and actions (for state policies)",
    )
    p.add_argument("--workers", type=int, help="worker processes (default: cores)")
    add_ray_flag(p)
    p.add_argument(
        "--noise",
        type=float,
        metavar="SIGMA",
        help="DART: Gaussian noise on the executed action (joint_position: rad a joint; "
        "ee_delta: m), the clean action recorded",
    )
    p.add_argument("--resume", action="store_true", help="continue an interrupted recording")
    p.add_argument("--replay", type=Path, metavar="DATASET", help="replay a dataset's actions")
    p.add_argument(
        "--frames", action="store_true",
        help="record the learned eyes' data (cubes seen by the perception cameras) into --out",
    )  # fmt: skip
    p.add_argument(
        "--starts", type=Path, metavar="FILE",
        help="record a start pool for a skill residual's task (--episodes starts)",
    )  # fmt: skip
    add_set_flag(p, "the scenario")
    return p


def main_record(argv: list[str] | None = None) -> int:
    from dataclasses import replace

    from cake_drake.learning.data import dataset
    from cake_drake.learning.data.recording import record, replay_check, spec_from_scenario
    from cake_drake.scenario import load_scenario

    args = record_parser().parse_args(argv)
    workers = worker_count(args.workers)
    if args.replay is not None:
        dataset.require_lerobot()
        result = replay_check(args.replay, workers)
        print(
            f"{args.replay}: {result['rebuilt']}/{result['episodes']} episodes rebuild the goal "
            "when their actions are replayed open loop"
        )
        return EXIT_OK
    if args.starts is not None:
        return _record_starts(args)
    if args.frames:
        return _record_frames(args, workers)
    if args.spec is None or args.out is None:
        raise InputError("record: give a scenario file and --out DATASET (or --replay DATASET)")
    if not 1 <= args.episodes <= 100_000:
        raise InputError(f"--episodes {args.episodes}: from 1 to 100000")
    scenario = load_scenario(args.spec, args.name, args.set)
    spec = spec_from_scenario(scenario, args.policy)
    if args.no_cameras:
        spec = replace(spec, cameras=())
    if args.noise is not None:
        from cake_drake.learning.rollout import check_noise

        spec = replace(spec, noise=check_noise(args.noise, spec.control_mode))
    seeds = [scenario.seed + k for k in range(args.episodes)]
    from dataclasses import asdict

    ray = ray_engine(args.ray, workers)
    training = asdict(scenario.training)
    report = record(spec, args.out, seeds, workers, args.resume, ray, args.name or "", training)
    noise = f", noise {spec.noise:g}" if spec.noise else ""
    print(
        f"{args.out}: {report['episodes']}/{report['tried']} episodes recorded "
        f"({report['frames']} frames at {report['fps']:g} Hz, {spec.control_mode}{noise}, "
        f"cameras {', '.join(report['cameras']) or 'none'}); {len(report['failed'])} failed "
        "(listed in report.json)"
    )
    return EXIT_OK


def _record_frames(args, workers: int) -> int:
    from cake_drake.learning.data.frames import FRAMES_SEED, record_frames

    if args.spec is not None or args.name is not None:
        raise InputError("record --frames draws its own scenes: give no SPEC or --name")
    if args.out is None:
        raise InputError("record --frames: give --out DIR, the dataset's folder")
    if not 1 <= args.episodes <= 10_000:
        raise InputError(f"--episodes {args.episodes}: runs to record, from 1 to 10000")
    seed = FRAMES_SEED
    for item in args.set or []:
        key, _, value = item.partition("=")
        if key != "seed" or not value.isdigit():
            raise InputError(f"--set {item}: record --frames reads only --set seed=S")
        seed = int(value)
    meta = record_frames(args.out, args.episodes, seed, workers,
                         progress=lambda line: print(line, flush=True))  # fmt: skip
    print(f"{args.out}: {meta['samples']} sightings of {len(meta['runs'])} runs (seeds "
          f"{meta['seeds'][0]}-{meta['seeds'][1]}) in {meta['minutes']:.1f} min")  # fmt: skip
    return EXIT_OK


def _record_starts(args) -> int:
    from cake_drake.learning.skills.train_residual import record_starts
    from cake_drake.scenario import load_scenario

    if args.spec is None:
        raise InputError("record --starts FILE: give the scenario file of a skill residual's task")
    if args.out is not None:
        raise InputError("record --starts FILE writes FILE: give no --out")
    if args.starts.exists():
        raise InputError(f"--starts {args.starts}: exists; give a path to a new file")
    if not args.starts.parent.is_dir():
        raise InputError(f"--starts {args.starts}: no folder {args.starts.parent} to write it in")
    if not 1 <= args.episodes <= 2_000:
        raise InputError(f"--episodes {args.episodes}: starts in the pool, from 1 to 2000")
    scenario = load_scenario(args.spec, args.name, args.set)
    written = record_starts(scenario, args.name or str(args.spec), args.starts, args.episodes)
    print(
        f"{args.starts}: {written} starts for CakeDrake/Skill-v0 (training.rl.starts: "
        f"{args.starts})"
    )
    return EXIT_OK
