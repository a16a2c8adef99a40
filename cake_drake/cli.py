"""Every command's argument parsing, in one place; the library never imports this module.

``cake-drake COMMAND ...`` (or ``python -m cake_drake.COMMAND ...``) with the commands
``run``, ``gains``, ``world``, ``plan``, ``validate`` and ``saycan``. Flags choose and
override; they carry no logic: ``run``'s flags only write fields of a
:class:`~cake_drake.scenario.Scenario`, and everything a flag can do a scenario file can
do too.

Exit codes (every command): 0 success; 1 no plan, or an invalid plan; 2 bad input
(one line on stderr, nothing written); 3 the plan could not be executed in the
simulated world. 130 when interrupted.
"""

from __future__ import annotations

import time

STARTED = time.perf_counter()

import argparse  # noqa: E402
import sys  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

from cake_drake.errors import (  # noqa: E402
    EXIT_EXECUTION_FAILED,
    EXIT_OK,
    CliParser,
    InputError,
    run_cli,
)

RUN_DOC = """Run the whole cake: plan a Blocksworld problem, execute it on a simulated Panda.

The planner's plan drives a Drake Diagram (action source -> WaypointIk -> controller ->
MultibodyPlant) that picks and stacks the cubes with a friction grasp. The verdict is
measured: the final cube poses, read back as PDDL facts, must satisfy the goal, and
every stacked cube must stand within 5 mm (xy) of the one below.

A run is a scenario (--scenario FILE [--name NAME]; models/scenarios/ has the shipped
ones); the flags below override its fields. Outputs in the output folder: plan.txt,
trajectory.npz, final_state.png, joint4_torque.png, summary.json, scenario.yaml (the
resolved scenario: run it again with --scenario to reproduce the run), and replay.html
with --meshcat. They are written whole or not at all.

Exit codes: 0 the goal was reached in the simulated world; 1 no plan (none exists, the
planner gave up at its limit, or the plan file is not a valid plan); 2 bad input;
3 the plan could not be executed (IK failure, or the goal not reached).
"""


def run_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="python -m cake_drake.run",
        description=RUN_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--scenario", type=Path, help="scenario file (YAML); default: the exercise")
    p.add_argument("--name", help="which scenario of a file that holds several")
    g = p.add_argument_group("overrides (each sets one scenario field)")
    g.add_argument(
        "--mode",
        choices=("position", "torque"),
        help="controller: torque = InverseDynamicsController (computed torque, !ComputedTorque); "
        "position = the plant's joint PD + feed-forward (!JointPd). Default: torque",
    )
    g.add_argument("--kp", type=float, nargs="+", help="controller gains kp, one or seven")
    g.add_argument("--kd", type=float, nargs="+", help="controller gains kd, one or seven")
    g.add_argument("--domain", type=Path, help="task.domain: PDDL domain file")
    g.add_argument("--problem", type=Path, help="task.problem: PDDL problem file")
    g.add_argument(
        "--plan", type=Path, help="task.plan: execute this plan file instead of planning"
    )
    g.add_argument("--planner", help="task.planner: a registry name or module:attribute")
    g.add_argument("--time-limit", type=float, help="task.time_limit: planner limit, s")
    g.add_argument("--ik", help="motion.ik: drake | dls | module:attribute")
    g.add_argument("--action-source", help="reference.action_source: plan | module:attribute")
    g.add_argument(
        "--reference", type=Path, help="reference: replay this trajectory.npz (!Recorded)"
    )
    g.add_argument(
        "--differentiate",
        choices=("spline", "central"),
        help="reference.differentiate: how the replay recovers q-dot and q-double-dot",
    )
    g.add_argument("--out", type=Path, help="outputs.folder (default: outputs/)")
    g.add_argument("--time-step", type=float, help="world.time_step, s (default 0.01)")
    g.add_argument("--slot-radius", type=float, help="world.slot_radius, m (default 0.55)")
    g.add_argument(
        "--no-collision-check", action="store_true", help="motion.collision_check: false"
    )
    g.add_argument(
        "--avoid-collisions",
        action="store_true",
        help="motion.avoid_collisions: re-plan colliding moves higher or with the hand turned",
    )
    g.add_argument("--seed", type=int, help="seed (the IK's random restarts draw from it)")
    g.add_argument(
        "--meshcat", action="store_true", help="visualization.meshcat: watch, save replay.html"
    )
    g.add_argument("--no-render", action="store_true", help="outputs.render: false")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def scenario_from_args(args: argparse.Namespace):
    """The scenario file (or the default) with every given flag written into it."""
    from cake_drake.scenario import (
        Planned,
        Recorded,
        Scenario,
        controller_for_mode,
        load_scenario,
        portable_path,
    )

    if args.name and not args.scenario:
        raise InputError("--name chooses a scenario of a --scenario file; give the file too")
    s = load_scenario(args.scenario, args.name) if args.scenario else Scenario()
    if args.mode and type(s.controller) is not type(controller_for_mode(args.mode)):
        s.controller = controller_for_mode(args.mode)
    for flag in ("kp", "kd"):
        values = getattr(args, flag)
        if values is not None:
            if not hasattr(s.controller, flag):
                raise InputError(
                    f"--{flag} sets the gains of !ComputedTorque or !JointPd; this scenario's "
                    f"controller is a {type(s.controller).__name__}: set its options instead"
                )
            setattr(s.controller, flag, list(values))
    task = s.task
    for flag, name in (("domain", "domain"), ("problem", "problem"), ("plan", "plan")):
        value = getattr(args, flag)
        if value is not None:
            setattr(task, name, portable_path(value))
    if args.planner is not None:
        task.planner = args.planner
    if args.time_limit is not None:
        task.time_limit = args.time_limit
    if args.ik is not None:
        s.motion.ik = args.ik
    if args.reference is not None:
        previous = s.reference
        s.reference = Recorded(portable_path(args.reference))
        if isinstance(previous, Recorded):
            s.reference.differentiate = previous.differentiate
    if args.differentiate is not None:
        if not isinstance(s.reference, Recorded):
            raise InputError("--differentiate goes with a recorded reference (--reference NPZ)")
        s.reference.differentiate = args.differentiate
    if args.action_source is not None:
        if not isinstance(s.reference, Planned):
            raise InputError("--action-source goes with a planned reference, not --reference")
        s.reference.action_source = args.action_source
    if args.out is not None:
        s.outputs.folder = str(args.out)
    if args.no_render:
        s.outputs.render = False
    if args.time_step is not None:
        s.world.time_step = args.time_step
    if args.slot_radius is not None:
        s.world.slot_radius = args.slot_radius
    if args.no_collision_check:
        s.motion.collision_check = False
    if args.avoid_collisions:
        s.motion.avoid_collisions = True
    if args.seed is not None:
        s.seed = args.seed
    if args.meshcat:
        s.visualization.meshcat = True
    return s


def main_run(argv: list[str] | None = None) -> int:
    from cake_drake.pipeline import run, tower_text

    args = run_parser().parse_args(argv)
    scenario = scenario_from_args(args)
    result = run(scenario, quiet=args.quiet, started=STARTED)
    e = result.execution
    rate = f"{e.sim_s:.1f} s simulated in {e.wall_s:.2f} s (RTF {e.rtf:.1f})"
    where = f"outputs in {scenario.outputs.folder}/"
    if result.success:
        print(f"goal reached: {tower_text(e)} — {rate}; {where}")
        return EXIT_OK
    print(f"error: plan not executed: {result.message} — {rate}; {where}", file=sys.stderr)
    return EXIT_EXECUTION_FAILED


GAINS_DOC = """Gains study: replay one recorded trajectory through InverseDynamicsController per Kd.

Exercise 4.x.3 asks what happens to tracking when the derivative gain drops from 20 to
5. The study replays the same reference (--reference, or one recorded first by a
position-mode run of the scenario's task) once per Kd, with the same Kp, and writes
kd_comparison.png (joint 4's tracking error and torque, one trace per Kd) and gains.json
(per Kd: RMS and max tracking error per joint, settling times, whether the tower was
built, measured from the poses).

Exit codes: 0 study done (whatever the towers did); 2 bad input; 3 the reference could
not be recorded.
"""


def gains_parser() -> argparse.ArgumentParser:
    p = CliParser(
        prog="python -m cake_drake.gains",
        description=GAINS_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--scenario", type=Path, help="base scenario (its task and world)")
    p.add_argument("--name", help="which scenario of a file that holds several")
    p.add_argument("--kd", type=float, nargs="+", default=[20.0, 5.0], help="Kd values (1/s)")
    p.add_argument("--kp", type=float, default=100.0, help="Kp for every run (1/s^2)")
    p.add_argument(
        "--reference",
        type=Path,
        help="trajectory.npz to replay (default: record one in position mode)",
    )
    p.add_argument("--differentiate", choices=("spline", "central"), default="spline")
    p.add_argument(
        "--problem",
        type=Path,
        help="the problem the reference was (or is to be) recorded on (default: problem_5)",
    )
    p.add_argument("--out", type=Path, default=Path("outputs"), help="output folder")
    p.add_argument("--quiet", action="store_true")
    return p


def main_gains(argv: list[str] | None = None) -> int:
    from cake_drake.gains import format_table, write_study
    from cake_drake.pipeline import check_output_folder
    from cake_drake.scenario import ComputedTorque, Recorded, Scenario, load_scenario, portable_path

    args = gains_parser().parse_args(argv)
    base = load_scenario(args.scenario, args.name) if args.scenario else Scenario()
    base.controller = ComputedTorque(kp=[args.kp])
    if args.problem is not None:
        base.task.problem = portable_path(args.problem)
    if args.reference is not None:
        base.reference = Recorded(portable_path(args.reference), args.differentiate)
    check_output_folder(args.out)
    table = write_study(base, args.kd, args.out)
    print(format_table(table))
    if not args.quiet:
        print(f"wrote {args.out}/kd_comparison.png and {args.out}/gains.json", file=sys.stderr)
    return EXIT_OK


WORLD_DOC = """Lay out a Blocksworld problem's initial state on the table and render it headless.

Exit codes: 0 rendered; 2 bad input (unreadable problem, more blocks or towers than
the world has cubes or slots, an initial state that is not a set of towers).
"""


def world_parser() -> argparse.ArgumentParser:
    from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, PROBLEM_5

    p = CliParser(
        prog="python -m cake_drake.world",
        description=WORLD_DOC,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--domain", type=Path, default=BLOCKSWORLD_DOMAIN)
    p.add_argument("--problem", type=Path, default=PROBLEM_5)
    p.add_argument("--render", type=Path, help="write a PNG of the initial state here")
    p.add_argument("--meshcat", action="store_true", help="also show it in Meshcat (local only)")
    return p


def main_world(argv: list[str] | None = None) -> int:
    from cake_drake.world.show import show_problem

    args = world_parser().parse_args(argv)
    if args.render is None and not args.meshcat:
        raise InputError("nothing to do: give --render out.png and/or --meshcat")
    if args.render is not None and args.render.suffix.lower() != ".png":
        raise InputError(f"{args.render}: the picture is written as PNG; name it *.png")
    for line in show_problem(args.domain, args.problem, args.render, args.meshcat):
        print(line)
    return EXIT_OK


def _delegate(module: str) -> Callable[[list[str] | None], int]:
    def main(argv: list[str] | None = None) -> int:
        import importlib

        return importlib.import_module(f"cake_drake.{module}").main(argv)

    return main


COMMANDS: dict[str, tuple[Callable[[list[str] | None], int], str]] = {
    "run": (main_run, "plan and execute a problem on the simulated Panda (a scenario)"),
    "gains": (main_gains, "the Kd study: replay one reference per Kd"),
    "world": (main_world, "lay out a problem's initial state and render it"),
    "plan": (_delegate("plan"), "plan only"),
    "validate": (_delegate("validate"), "check a plan against a problem, VAL-style"),
    "saycan": (_delegate("saycan"), "map a SayCan-style transcript onto the kitchen domain"),
}


def main(argv: list[str] | None = None) -> int:
    """``cake-drake COMMAND [ARGS]``: the console script."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: cake-drake COMMAND [ARGS ...]\n\ncommands:")
        for name, (_, summary) in COMMANDS.items():
            print(f"  {name:<9} {summary}")
        print("\n`cake-drake COMMAND --help` describes one.")
        return EXIT_OK if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(
            f"error: cake-drake: unknown command {name!r}; choose one of: " + ", ".join(COMMANDS),
            file=sys.stderr,
        )
        return 2
    return run_cli(COMMANDS[name][0], rest)


def console() -> None:
    sys.exit(main())
