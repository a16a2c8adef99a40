"""``world``: lay out a problem's initial state on the table and render it headless."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from pydrake.geometry import StartMeshcat
from pydrake.math import RigidTransform
from pydrake.systems.framework import DiagramBuilder

from cake_drake.commands.common import CliParser
from cake_drake.errors import EXIT_OK, InputError
from cake_drake.outputs.files import check_output_file
from cake_drake.outputs.replay import add_visualization
from cake_drake.pipeline import load_world_problem
from cake_drake.symbolic import BLOCKSWORLD_DOMAIN, PROBLEM_5, towers
from cake_drake.world.render import Renderer, save_png
from cake_drake.world.scene import WorldConfig, add_world, cube_colours, layout

WORLD_DOC = """Lay out a Blocksworld problem's initial state on the table and render it headless.

Exit codes: 0 rendered; 2 bad input (unreadable problem, more blocks or towers than
the world has cubes or slots, an initial state that is not a set of towers).
"""


def world_parser() -> argparse.ArgumentParser:
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
    args = world_parser().parse_args(argv)
    if args.render is None and not args.meshcat:
        raise InputError("nothing to do: give --render out.png and/or --meshcat")
    render = None
    if args.render is not None:
        if args.render.suffix.lower() != ".png":
            raise InputError(f"{args.render}: the picture is written as PNG; name it *.png")
        render = check_output_file(args.render)
        if not render.parent.is_dir():
            raise InputError(f"{args.render}: cannot write the picture there (no such folder)")
    for line in show_problem(args.domain, args.problem, render, args.meshcat):
        print(line)
    return EXIT_OK


def show_problem(
    domain: Path, problem_path: Path, render: Path | None = None, meshcat: bool = False
) -> list[str]:
    """Lay out the problem's initial towers; write ``render`` (PNG) and/or show them in
    Meshcat. Returns one line per tower, top first, with the cubes' colours."""
    problem = load_world_problem(domain, problem_path)
    stacks = towers(problem.init)
    poses = layout(stacks)
    blocks = sorted(problem.objects)
    colours = {b: name for b, (name, _) in cube_colours(blocks).items()}
    lines = []
    if render is not None:
        save_png(Renderer(blocks).render(poses), render)
        lines.append(f"wrote {render}")
    if meshcat:
        _show_in_meshcat(blocks, poses)
    for tower in stacks:
        lines.append("tower: " + " on ".join(f"{b} ({colours[b]})" for b in reversed(tower)))
    return lines


def _show_in_meshcat(blocks: Sequence[str], poses: dict[str, RigidTransform]) -> None:
    meshcat = StartMeshcat()
    builder = DiagramBuilder()
    scene = add_world(builder, blocks, WorldConfig(time_step=0.0), initial_poses=poses)
    add_visualization(builder, scene.scene_graph, meshcat)
    diagram = builder.Build()
    diagram.ForcedPublish(diagram.CreateDefaultContext())
    print(f"Meshcat at {meshcat.web_url()}")
    if sys.stdin.isatty():
        try:
            input("press Enter to quit ")
        except EOFError:
            pass
