"""Show a Blocksworld problem's initial state: a headless picture, or Meshcat."""

import sys
from collections.abc import Sequence
from pathlib import Path

from pydrake.math import RigidTransform

from cake_drake.world.scene import cube_colours, layout


def show_problem(
    domain: Path, problem_path: Path, render: Path | None = None, meshcat: bool = False
) -> list[str]:
    """Lay out the problem's initial towers; write ``render`` (PNG) and/or show them in
    Meshcat. Returns one line per tower, top first, with the cubes' colours."""
    from cake_drake.pipeline import load_world_problem
    from cake_drake.symbolic import towers

    problem = load_world_problem(domain, problem_path)
    stacks = towers(problem.init)
    poses = layout(stacks)
    blocks = sorted(problem.objects)
    colours = {b: name for b, (name, _) in cube_colours(blocks).items()}
    lines = []
    if render is not None:
        from cake_drake.world.render import Renderer, save_png

        save_png(Renderer(blocks).render(poses), render)
        lines.append(f"wrote {render}")
    if meshcat:
        _show_in_meshcat(blocks, poses)
    for tower in stacks:
        lines.append("tower: " + " on ".join(f"{b} ({colours[b]})" for b in reversed(tower)))
    return lines


def _show_in_meshcat(blocks: Sequence[str], poses: dict[str, RigidTransform]) -> None:
    from pydrake.geometry import StartMeshcat
    from pydrake.systems.framework import DiagramBuilder

    from cake_drake.outputs.replay import add_visualization
    from cake_drake.world.scene import WorldConfig, add_world

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
