"""``run``: plan a Blocksworld problem and execute it on the simulated Panda.

Its flags write fields of the :class:`~cake_drake.scenario.Scenario` (``scenario_from_args``);
the run itself is :func:`cake_drake.pipeline.run`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.commands import STARTED
from cake_drake.commands.common import CliParser, add_set_flag, check_time_limit
from cake_drake.errors import EXIT_EXECUTION_FAILED, EXIT_OK, InputError

RUN_DOC = """Run the whole cake: plan a Blocksworld problem, execute it on a simulated Panda.

The planner's plan drives a Drake Diagram (action source -> WaypointIk -> controller ->
MultibodyPlant) that picks and stacks the cubes with a friction grasp. The verdict is
measured: the final cube poses, read back as PDDL facts, must satisfy the goal, and
every stacked cube must stand within 5 mm (xy) of the one below.

A run is a scenario (--scenario FILE [--name NAME]; models/scenarios/ has the shipped
ones); the flags below override its fields. Outputs in the output folder: plan.txt,
trajectory.npz, final_state.png, joint4_torque.png, cake.png (the run's three layers,
each classical or learned), summary.json, scenario.yaml (the
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
        choices=("position", "torque", "pid"),
        help="controller: torque = InverseDynamicsController (computed torque, !ComputedTorque); "
        "position = the plant's joint PD + feed-forward (!JointPd); pid = Drake's "
        "PidController + gravity compensation (!Pid). Default: torque",
    )
    g.add_argument("--kp", type=float, nargs="+", help="controller gains kp, one or seven")
    g.add_argument("--kd", type=float, nargs="+", help="controller gains kd, one or seven")
    g.add_argument("--domain", type=Path, help="task.domain: PDDL domain file")
    g.add_argument("--problem", type=Path, help="task.problem: PDDL problem file")
    g.add_argument(
        "--plan", type=Path, help="task.plan: execute this plan file instead of planning"
    )
    g.add_argument(
        "--planner",
        help="task.planner: a registry name, learned@DIR (a learned planner's checkpoint) or "
        "module:attribute",
    )
    g.add_argument("--time-limit", type=float, help="task.time_limit: planner limit, s")
    g.add_argument("--ik", help="motion.ik: drake | dls | module:attribute")
    g.add_argument(
        "--perception",
        help="perception.estimator: where the cake reads the cubes from: truth (the "
        "simulator's own poses; default) | depth (the cameras: colour, depth, ICP) | oracle "
        "| learned (the cameras read by the shipped point network) | learned@DIR",
    )
    g.add_argument(
        "--depth-noise",
        action="store_true",
        help="perception.noise.model: axial (the depth cameras' noise, seeded by --seed)",
    )
    g.add_argument(
        "--action-source", help="reference.action_source: monitor | plan | module:attribute"
    )
    g.add_argument(
        "--no-monitor",
        action="store_true",
        help="reference.action_source: plan (open loop: no checks against the world, no replans)",
    )
    g.add_argument(
        "--fault",
        action="append",
        metavar="SPEC",
        help="add a fault (repeatable): slip:K | knock:CUBE@T | move:CUBE@T:X,Y | random:SEED",
    )
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
        "--slot-spacing",
        type=float,
        help="world.slot_spacing and world.slot_spacing_max: the slots stand this far apart, m "
        "(default: 0.144 to 0.2, spread as the plan allows)",
    )
    g.add_argument(
        "--no-collision-check", action="store_true", help="motion.collision_check: false"
    )
    g.add_argument(
        "--avoid-collisions",
        action="store_true",
        help="motion.avoid_collisions: re-plan colliding moves higher or with the hand turned",
    )
    g.add_argument(
        "--motion-planner",
        help="motion.planner: straight | rrt-connect | module:attribute",
    )
    g.add_argument("--seed", type=int, help="seed (the IK's random restarts draw from it)")
    g.add_argument(
        "--meshcat", action="store_true", help="visualization.meshcat: watch, save replay.html"
    )
    g.add_argument("--no-render", action="store_true", help="outputs.render: false")
    g.add_argument(
        "--cameras",
        action="store_true",
        help="cameras: the default scene and wrist cameras (224 x 224), when the scenario has "
        "none; each camera's last frame is written as camera_<name>.png",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_set_flag(p, "the scenario")
    return p


def scenario_from_args(args: argparse.Namespace):
    """The scenario file (or the default) with every given flag written into it."""
    from cake_drake.scenario import (
        LEARNED_AT,
        Planned,
        Recorded,
        Scenario,
        controller_for_mode,
        load_scenario,
        portable_path,
        with_settings,
    )

    if args.name and not args.scenario:
        raise InputError("--name chooses a scenario of a --scenario file; give the file too")
    if args.scenario:
        s = load_scenario(args.scenario, args.name, args.set)
    else:
        s = with_settings(Scenario(), args.set)
    if args.mode and type(s.controller) is not type(controller_for_mode(args.mode)):
        s.controller = controller_for_mode(args.mode)
    for flag in ("kp", "kd"):
        values = getattr(args, flag)
        if values is not None:
            if not hasattr(s.controller, flag):
                raise InputError(
                    f"--{flag} sets the gains of !ComputedTorque, !JointPd or !Pid; this "
                    f"scenario's controller is a {type(s.controller).__name__}: set its "
                    "options instead"
                )
            setattr(s.controller, flag, list(values))
    task = s.task
    for flag, name in (("domain", "domain"), ("problem", "problem"), ("plan", "plan")):
        value = getattr(args, flag)
        if value is not None:
            setattr(task, name, portable_path(value))
    if args.planner is not None:
        task.planner = args.planner
        prefix, _, folder = args.planner.partition(LEARNED_AT)
        if not prefix and folder:  # a learned planner's folder: from here, saved absolute
            task.planner = LEARNED_AT + portable_path(folder)
    if args.time_limit is not None:
        task.time_limit = check_time_limit(args.time_limit)
    if args.ik is not None:
        s.motion.ik = args.ik
    if args.perception is not None:
        s.perception.estimator = args.perception
    if args.depth_noise:
        s.perception.noise.model = "axial"
    if args.reference is not None:
        previous = s.reference
        s.reference = Recorded(portable_path(args.reference))
        if isinstance(previous, Recorded):
            s.reference.differentiate = previous.differentiate
    if args.differentiate is not None:
        if not isinstance(s.reference, Recorded):
            raise InputError("--differentiate goes with a recorded reference (--reference NPZ)")
        s.reference.differentiate = args.differentiate
    if args.action_source is not None and args.no_monitor:
        raise InputError("--no-monitor and --action-source both choose the action source")
    if args.no_monitor:
        args.action_source = "plan"
    if args.action_source is not None:
        if not isinstance(s.reference, Planned):
            raise InputError("--action-source goes with a planned reference, not --reference")
        s.reference.action_source = args.action_source
    if args.fault:
        from cake_drake.world.faults import parse_fault

        s.faults = [*s.faults, *(parse_fault(spec) for spec in args.fault)]
    if args.out is not None:
        s.outputs.folder = str(args.out)
    if args.no_render:
        s.outputs.render = False
    if args.time_step is not None:
        s.world.time_step = args.time_step
    if args.slot_radius is not None:
        s.world.slot_radius = args.slot_radius
    if args.slot_spacing is not None:
        s.world.slot_spacing = s.world.slot_spacing_max = args.slot_spacing
    if args.no_collision_check:
        s.motion.collision_check = False
    if args.avoid_collisions:
        s.motion.avoid_collisions = True
    if args.motion_planner is not None:
        s.motion.planner = args.motion_planner
    if args.seed is not None:
        s.seed = args.seed
    if args.meshcat:
        s.visualization.meshcat = True
        if sys.stdin.isatty():  # someone is watching: real time, and the viewer stays
            s.visualization.realtime_rate = 1.0
    if args.cameras and not s.cameras:
        from cake_drake.world.cameras import default_cameras

        s.cameras = default_cameras()
    return s


def main_run(argv: list[str] | None = None) -> int:
    from cake_drake.pipeline import run, tower_text

    args = run_parser().parse_args(argv)
    scenario = scenario_from_args(args)
    result = run(scenario, quiet=args.quiet, started=STARTED)
    if not args.quiet:
        from cake_drake.outputs.report import layers, layers_line

        print(layers_line(layers(scenario, result.plan)), file=sys.stderr)
    e = result.execution
    rate = f"{e.sim_s:.1f} s simulated in {e.wall_s:.2f} s (RTF {e.rtf:.1f})"
    events = e.monitoring.get("events", [])
    if events:
        replans = e.monitoring.get("replans", 0)
        told = (
            f"{len(events)} disagreement{'s' * (len(events) > 1)} with the plan "
            f"({replans} replan{'s' * (replans != 1)})"
        )
        rate = (f"recovered after {told}" if result.success else f"after {told}") + " — " + rate
    where = f"outputs in {scenario.outputs.folder}/"
    if result.success:
        print(f"goal reached: {tower_text(e)} — {rate}; {where}")
    else:
        print(f"error: plan not executed: {result.message} — {rate}; {where}", file=sys.stderr)
    if scenario.visualization.meshcat and sys.stdin.isatty():
        _keep_viewer_open()
    return EXIT_OK if result.success else EXIT_EXECUTION_FAILED


def _keep_viewer_open() -> None:
    """Meshcat's server lives as long as this process: wait until the user is done."""
    print(
        "Meshcat keeps the run (Animations: play it again); press Enter or Ctrl-C to close",
        file=sys.stderr,
        flush=True,
    )
    try:
        sys.stdin.readline()
    except KeyboardInterrupt:
        pass
