"""Lay out a Blocksworld problem's initial state on the table and render it headless.

    python -m cake_drake.world [--problem P] --render out.png [--meshcat]

Exit codes: 0 rendered; 2 bad input (unreadable problem, more blocks or towers than
the world has cubes or slots, an initial state that is not a set of towers).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from cake_drake.errors import EXIT_OK, CliParser, InputError, run_cli
from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, PROBLEM_5, towers


def main(argv: list[str] | None = None) -> int:
    p = CliParser(
        prog="python -m cake_drake.world",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--domain", type=Path, default=BLOCKSWORLD_DOMAIN)
    p.add_argument("--problem", type=Path, default=PROBLEM_5)
    p.add_argument("--render", type=Path, help="write a PNG of the initial state here")
    p.add_argument("--meshcat", action="store_true", help="also show it in Meshcat (local only)")
    args = p.parse_args(argv)
    if args.render is None and not args.meshcat:
        raise InputError("nothing to do: give --render out.png and/or --meshcat")

    from cake_drake.run import load_world_problem
    from cake_drake.world.scene import CUBE_COLOURS, cube_models, layout

    problem = load_world_problem(args.domain, args.problem)
    stacks = towers(problem.init)
    poses = layout(stacks)
    colours = {b: CUBE_COLOURS[k] for b, k in cube_models(problem.objects).items()}
    if args.render is not None:
        from cake_drake.world.render import Renderer, save_png

        if args.render.suffix.lower() != ".png":
            raise InputError(f"{args.render}: the picture is written as PNG; name it *.png")
        save_png(Renderer(sorted(problem.objects)).render(poses), args.render)
        print(f"wrote {args.render}")
    if args.meshcat:
        _show_in_meshcat(sorted(problem.objects), poses)
    for tower in stacks:
        print("tower: " + " on ".join(f"{b} ({colours[b]})" for b in reversed(tower)))
    return EXIT_OK


def _show_in_meshcat(blocks, poses) -> None:
    from pydrake.geometry import StartMeshcat
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.visualization import AddDefaultVisualization

    from cake_drake.world.scene import WorldConfig, add_world, set_cube_poses

    meshcat = StartMeshcat()
    builder = DiagramBuilder()
    scene = add_world(builder, blocks, WorldConfig(time_step=0.0))
    AddDefaultVisualization(builder, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    set_cube_poses(scene, scene.plant.GetMyMutableContextFromRoot(context), poses)
    diagram.ForcedPublish(context)
    print(f"Meshcat at {meshcat.web_url()}")
    if sys.stdin.isatty():
        try:
            input("press Enter to quit ")
        except EOFError:
            pass


if __name__ == "__main__":
    sys.exit(run_cli(main))
