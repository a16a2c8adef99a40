"""Run the whole cake: plan a Blocksworld problem, execute it on a simulated Franka Panda.

The planner's plan drives a Drake Diagram (PlanSource -> WaypointIk -> controller ->
MultibodyPlant) that picks and stacks the cubes with a friction grasp. The verdict is
measured: the final cube poses, read back as PDDL facts, must satisfy the goal, and
every stacked cube must stand within 5 mm (xy) of the one below.

Outputs in --out: plan.txt, trajectory.npz, final_state.png, joint4_torque.png,
summary.json (and replay.html with --meshcat). They are written whole or not at all.

Exit codes: 0 the goal was reached in the simulated world; 1 no plan (none exists, the
planner gave up at its limit, or the --plan file is not a valid plan); 2 bad input;
3 the plan could not be executed (IK failure, or the goal not reached).
"""

from __future__ import annotations

import time

_T_START = time.perf_counter()

import argparse  # noqa: E402
import sys  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

from cake_drake.diagram import MODES, CakeDiagram, RunConfig, build_diagram  # noqa: E402
from cake_drake.errors import (  # noqa: E402
    EXIT_EXECUTION_FAILED,
    EXIT_OK,
    CliParser,
    InputError,
    NoPlanError,
    run_cli,
)
from cake_drake.execution import STACK_TOL, Execution, ProgressBar, execute  # noqa: E402
from cake_drake.geometric.ik import SOLVERS  # noqa: E402
from cake_drake.symbolic import (  # noqa: E402
    BLOCKSWORLD_DOMAIN,
    DEFAULT_PLANNER,
    PLANNERS,
    PROBLEM_5,
    PROBLEM_5_OPTIMAL_LENGTH,
    Plan,
    Problem,
    check_state,
    fact_str,
    is_blocksworld,
    load_problem,
    read_plan,
    solve_problem,
    towers,
    validate_plan,
)
from cake_drake.world.scene import layout  # noqa: E402


@dataclass
class RunResult:
    """What a run produced, for the CLI, the benchmarks and the notebooks."""

    success: bool
    message: str
    plan: Plan
    execution: Execution
    cake: CakeDiagram
    stages: dict[str, float] = field(default_factory=dict)
    written: list[Path] = field(default_factory=list)
    unmet: list[str] = field(default_factory=list)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = CliParser(
        prog="python -m cake_drake.run",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--mode",
        choices=MODES,
        default="torque",
        help="dynamic layer: torque = InverseDynamicsController (computed torque); "
        "position = joint PD + feed-forward (default: %(default)s)",
    )
    p.add_argument("--domain", type=Path, default=BLOCKSWORLD_DOMAIN, help="PDDL domain file")
    p.add_argument(
        "--problem",
        type=Path,
        default=PROBLEM_5,
        help="PDDL problem file (default: problem_5, the exercise's five blocks)",
    )
    p.add_argument(
        "--plan",
        type=Path,
        default=None,
        help="execute this plan file (plan.txt, .soln or sas_plan) for the problem "
        "instead of planning; it is validated first",
    )
    p.add_argument(
        "--planner",
        default=DEFAULT_PLANNER,
        help=f"one of {', '.join(PLANNERS)} (default: %(default)s)",
    )
    p.add_argument("--time-limit", type=float, default=None, help="planner time limit, s")
    p.add_argument(
        "--ik", default="drake", help=f"IK solver: {' | '.join(SOLVERS)} (default: drake)"
    )
    p.add_argument(
        "--kp",
        type=float,
        nargs="+",
        default=[100.0],
        help="torque mode: proportional gain, one value or seven (default: 100)",
    )
    p.add_argument(
        "--kd",
        type=float,
        nargs="+",
        default=[20.0],
        help="torque mode: derivative gain, one value or seven (default: 20)",
    )
    p.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="replay this trajectory.npz (from an earlier run) instead of planning",
    )
    p.add_argument(
        "--differentiate",
        choices=("spline", "central"),
        default="spline",
        help="how the replay recovers velocity and acceleration (default: spline)",
    )
    p.add_argument(
        "--out", type=Path, default=Path("outputs"), help="output folder (default: outputs/)"
    )
    p.add_argument(
        "--time-step", type=float, default=0.01, help="simulation step, s (default: 0.01)"
    )
    p.add_argument(
        "--no-collision-check",
        action="store_true",
        help="do not check the planned moves for collisions with other cubes",
    )
    p.add_argument(
        "--avoid-collisions",
        action="store_true",
        help="raise the transit height (up to 3 x 5 cm) until no planned move hits a cube",
    )
    p.add_argument(
        "--slot-radius",
        type=float,
        default=0.55,
        help="distance of the table slots from the robot base, m (default: 0.55); "
        "try 1.0 to see an IK failure",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seed for IK restarts (runs are deterministic)"
    )
    p.add_argument(
        "--meshcat", action="store_true", help="show the run live in Meshcat and save replay.html"
    )
    p.add_argument("--no-render", action="store_true", help="skip final_state.png")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p.parse_args(argv)


def _gains(values: list[float], flag: str) -> float | list[float]:
    if len(values) not in (1, 7):
        raise InputError(f"{flag} takes one value or seven (one per joint), got {len(values)}")
    return values[0] if len(values) == 1 else values


def make_config(args: argparse.Namespace) -> RunConfig:
    from cake_drake.world.scene import WorldConfig

    if not 0.2 <= args.slot_radius <= 2.0:
        raise InputError(f"--slot-radius {args.slot_radius} is outside 0.2 to 2.0 m")
    if not 0.0005 <= args.time_step <= 0.02:
        raise InputError(f"--time-step {args.time_step} is outside 0.0005 to 0.02 s")
    config = RunConfig(
        mode=args.mode,
        kp=_gains(args.kp, "--kp"),
        kd=_gains(args.kd, "--kd"),
        ik=args.ik,
        seed=args.seed,
        world=WorldConfig(time_step=args.time_step, slot_radius=args.slot_radius),
        reference=args.reference,
        differentiate=args.differentiate,
        check_collisions=not args.no_collision_check,
        avoid_collisions=args.avoid_collisions,
    )
    if args.reference is not None and args.mode != "torque":
        raise InputError("--reference replays through InverseDynamicsController: use --mode torque")
    if args.ik not in SOLVERS:
        raise InputError(f"unknown IK solver {args.ik!r}; choose one of: {', '.join(SOLVERS)}")
    config.check()
    return config


def load_world_problem(domain: Path, problem_path: Path) -> Problem:
    """A Blocksworld problem whose initial state the world can lay out."""
    problem = load_problem(domain, problem_path)
    if not is_blocksworld(problem.domain):
        raise InputError(
            f"{domain}: the simulated world runs Blocksworld (predicates on, on-table, clear, "
            "holding, arm-empty; actions pick-up, put-down, stack, unstack)"
        )
    issues = check_state(problem.init, problem.objects)
    if issues:
        raise InputError(f"{problem_path}: the initial state cannot be laid out: {issues[0]}")
    return problem


def get_plan(
    problem: Problem,
    planner: str = DEFAULT_PLANNER,
    plan_path: Path | None = None,
    time_limit: float | None = None,
) -> Plan:
    """Plan with ``planner``, or read and validate the plan file ``plan_path``."""
    if plan_path is None:
        return solve_problem(problem, planner, time_limit)
    actions = read_plan(plan_path)
    check = validate_plan(problem, actions)
    if not check.ok:
        raise NoPlanError(
            f"{plan_path}: not a valid plan for {problem.problem_path}: {check.message}"
        )
    return Plan(actions, f"file {plan_path}", "-", "-", 0.0, False)


def verdict(problem: Problem, execution: Execution) -> tuple[bool, list[str], str]:
    """(success, unmet goal facts, one-line message), from the measured poses."""
    if execution.error is not None:
        return False, [], execution.error
    facts = execution.reading.facts
    unmet = [fact_str(f) for f in sorted(problem.goal - facts)]
    loose = [
        f"{b} stands {off * 1000:.1f} mm off the cube below (tolerance {STACK_TOL * 1000:.0f} mm)"
        for b, off in sorted(execution.offsets.items())
        if off > STACK_TOL and any(g[0] == "on" and g[1] == b for g in problem.goal)
    ]
    if unmet or loose:
        parts = []
        if unmet:
            parts.append("goal facts not true in the simulated world: " + " ".join(unmet))
        if loose:
            parts.append("; ".join(loose))
        if execution.reading.problems:
            parts.append("; ".join(execution.reading.problems))
        return False, unmet, "; ".join(parts)
    return True, [], "goal reached in the simulated world"


def tower_text(execution: Execution) -> str:
    """The towers standing at the end, top first, and the largest stacking offset."""
    lines = [" on ".join(reversed(t)) for t in towers(execution.reading.facts) if len(t) > 1]
    worst = max(execution.offsets.values(), default=0.0) * 1000
    return f"{'; '.join(lines) or 'no tower'} (largest xy offset {worst:.1f} mm)"


def run(
    config: RunConfig,
    problem_path: Path = PROBLEM_5,
    domain_path: Path = BLOCKSWORLD_DOMAIN,
    planner: str = DEFAULT_PLANNER,
    plan_path: Path | None = None,
    time_limit: float | None = None,
    out: Path | None = Path("outputs"),
    render: bool = True,
    quiet: bool = True,
    meshcat=None,
    settle_s: float = 0.3,
) -> RunResult:
    """The whole pipeline: problem -> plan -> Diagram -> simulation -> verdict -> outputs.

    ``out=None`` writes nothing (for notebooks and studies); ``meshcat`` is an optional
    ``pydrake.geometry.Meshcat`` to watch (and record to ``replay.html``); ``settle_s`` is
    how long the world runs on after the last action before the poses are read.
    """
    stages: dict[str, float] = {"import": time.perf_counter() - _T_START}
    config.check()
    t = time.perf_counter()
    problem = load_world_problem(domain_path, problem_path)
    blocks = sorted(problem.objects)
    initial = layout(towers(problem.init), config.world.slots)
    worker = None
    if out is not None:
        from cake_drake.outputs.worker import OutputWorker

        worker = OutputWorker(blocks, initial, render=render)
    try:
        plan = get_plan(problem, planner, plan_path, time_limit)
        stages["planning"] = time.perf_counter() - t
        if not quiet and plan_path is None:
            print(plan.note(), file=sys.stderr)
            if (
                problem.problem_path.endswith("problem_5.pddl")
                and plan.length != PROBLEM_5_OPTIMAL_LENGTH
            ):
                print(
                    f"note: problem_5's optimal plan has {PROBLEM_5_OPTIMAL_LENGTH} actions; "
                    f"{planner} is satisficing",
                    file=sys.stderr,
                )

        t = time.perf_counter()
        cake = build_diagram(config, blocks, initial, plan.actions, meshcat=meshcat)
        stages["diagram_build"] = time.perf_counter() - t

        n = plan.length if config.reference is None else len(cake.reference.actions)
        progress = ProgressBar(
            n, lambda k: f"({plan.actions[k]})" if k < plan.length else "", enabled=not quiet
        )
        if meshcat is not None:
            meshcat.StartRecording()
        execution = execute(cake, n, settle_s=settle_s, progress=progress)
        for warning in execution.warnings:
            print(f"warning: collision: {warning}", file=sys.stderr)
        stages["simulation"] = execution.wall_s
        if cake.ik is not None:
            stages["ik"] = sum(cake.ik.times_ms) / 1000
        success, unmet, message = verdict(problem, execution)
        result = RunResult(success, message, plan, execution, cake, stages, [], unmet)
        if out is None:
            return result

        from cake_drake.outputs.files import OutputDir
        from cake_drake.outputs.report import write_outputs

        staged = OutputDir(out)
        try:
            write_outputs(staged, problem, result, worker, render, meshcat)
            result.written = staged.commit()
        except BaseException:
            staged.discard()
            raise
        return result
    finally:
        if worker is not None:
            worker.close()


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    meshcat = None
    if args.meshcat:
        from pydrake.geometry import StartMeshcat

        meshcat = StartMeshcat()
    result = run(
        make_config(args),
        problem_path=args.problem,
        domain_path=args.domain,
        planner=args.planner,
        plan_path=args.plan,
        time_limit=args.time_limit,
        out=args.out,
        render=not args.no_render,
        quiet=args.quiet,
        meshcat=meshcat,
    )
    e = result.execution
    rate = f"{e.sim_s:.1f} s simulated in {e.wall_s:.2f} s (RTF {e.rtf:.1f})"
    where = f"outputs in {args.out}/"
    if result.success:
        print(f"goal reached: {tower_text(e)} — {rate}; {where}")
        return EXIT_OK
    print(f"error: plan not executed: {result.message} — {rate}; {where}", file=sys.stderr)
    return EXIT_EXECUTION_FAILED


if __name__ == "__main__":
    sys.exit(run_cli(main))
