"""World layer: the offline Panda, cubes that hold a stack, facts from poses, rendering."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from matplotlib.colors import rgb_to_hsv
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from cake_drake.errors import InputError
from cake_drake.symbolic import (
    BLOCKSWORLD_DOMAIN,
    PROBLEM_5,
    load_problem,
    parse_domain,
    parse_problem,
    random_problem,
    towers,
)
from cake_drake.world.facts import read_facts
from cake_drake.world.scene import (
    CUBE_SIZE,
    Q_HOME,
    SLOTS,
    WorldConfig,
    add_world,
    cube_colours,
    cube_poses,
    layout,
    make_control_plant,
    make_slots,
    set_arm_positions,
    set_cube_poses,
)

BLOCKS5 = list("abcde")


def test_model_loads_offline_without_mass_or_inertia_warnings(caplog):
    caplog.set_level(logging.WARNING)
    scene = add_world(DiagramBuilder(), BLOCKS5)
    control = make_control_plant()
    text = " ".join(r.getMessage().lower() for r in caplog.records)
    assert "mass" not in text and "inertia" not in text and "material" not in text
    assert scene.plant.num_actuated_dofs() == 9
    assert scene.plant.num_actuated_dofs(scene.arm) == 7
    assert scene.plant.num_actuated_dofs(scene.hand) == 2
    assert control.num_actuated_dofs() == 7 and control.num_positions() == 7


def test_links_have_realistic_inertia_and_datasheet_limits():
    scene = add_world(DiagramBuilder(), [])
    plant = scene.plant
    context = plant.CreateDefaultContext()
    total = plant.CalcTotalMass(context, [scene.arm])
    assert 15.0 < total < 20.0  # the Panda arm is about 18 kg
    for i in range(8):
        body = plant.GetBodyByName(f"panda_link{i}", scene.arm)
        M = body.CalcSpatialInertiaInBodyFrame(context)
        I_cm = M.Shift(M.get_com()).CalcRotationalInertia().CopyToFullMatrix3()
        assert M.get_mass() > 0.1
        assert not np.allclose(np.diag(I_cm), 0.1), f"link{i} has the placeholder inertia"
        assert np.all(np.diag(I_cm) < 0.05)
    efforts = [
        plant.get_joint_actuator(a).effort_limit() for a in plant.GetJointActuatorIndices(scene.arm)
    ]
    assert efforts == [87.0] * 4 + [12.0] * 3
    j4 = plant.GetJointByName("panda_joint4", scene.arm)
    assert j4.position_lower_limits()[0] == pytest.approx(-3.0718)
    assert j4.position_upper_limits()[0] == pytest.approx(-0.0698)


def _hold_arm_sources(builder, scene):
    """Hold the arm away from the cubes on the plant's PD and keep the fingers open."""
    q_away = Q_HOME.copy()
    q_away[0] = 2.0
    src = builder.AddSystem(ConstantVectorSource(np.concatenate([q_away, np.zeros(7)])))
    builder.Connect(src.get_output_port(), scene.plant.get_desired_state_input_port(scene.arm))
    fingers = builder.AddSystem(ConstantVectorSource([0.04, 0.04, 0.0, 0.0]))
    builder.Connect(fingers.get_output_port(), scene.plant.get_desired_state_input_port(scene.hand))
    return q_away


@pytest.mark.parametrize("n", [5, 10])
def test_a_tower_of_cubes_holds(n):
    blocks = list("abcdefghij")[:n]
    builder = DiagramBuilder()
    scene = add_world(builder, blocks, WorldConfig(), arm_gains=([600.0] * 7, [50.0] * 7))
    q_away = _hold_arm_sources(builder, scene)
    diagram = builder.Build()
    sim = Simulator(diagram)
    context = scene.plant.GetMyMutableContextFromRoot(sim.get_mutable_context())
    start = layout([blocks])
    set_cube_poses(scene, context, start)
    set_arm_positions(scene, context, q_away)
    sim.AdvanceTo(5.0)
    end = cube_poses(scene, context)
    top = blocks[-1]
    sag = start[top].translation()[2] - end[top].translation()[2]
    assert -0.0005 < sag < 0.002, f"top cube sagged {sag * 1000:.2f} mm"  # laid out pressed
    for b in blocks:
        slide = np.linalg.norm(end[b].translation()[:2] - start[b].translation()[:2])
        assert slide < 0.0005, f"{b} slid {slide * 1000:.2f} mm"


def test_facts_round_trip_problem_5_and_generated():
    problem = load_problem(BLOCKSWORLD_DOMAIN, PROBLEM_5)
    cases = [problem]
    domain = parse_domain(BLOCKSWORLD_DOMAIN.read_text())
    for n, seed in [(3, 1), (6, 2), (8, 3)]:
        cases.append(parse_problem(domain, random_problem(n, seed)))
    for p in cases:
        reading = read_facts(layout(towers(p.init)))
        expected = {f for f in p.init if f[0] in ("on", "on-table", "clear")}
        assert reading.facts == expected
        assert reading.problems == ()


def test_facts_flag_tilted_and_floating_cubes():
    poses = {
        "a": RigidTransform(RollPitchYaw(0.5, 0, 0), [0.5, 0, CUBE_SIZE / 2]),
        "b": RigidTransform([0.5, 0.2, 0.15]),
        "c": RigidTransform(RollPitchYaw(0, 0, 0.3), [0.5, -0.2, CUBE_SIZE / 2]),
    }
    reading = read_facts(poses)
    assert reading.facts == {("on-table", "c"), ("clear", "c")}
    assert any("a is tilted" in p for p in reading.problems)
    assert any("b rests on nothing" in p for p in reading.problems)


def test_more_towers_than_the_table_holds_is_bad_input():
    assert len(SLOTS) == 12
    layout([[f"b{i}"] for i in range(12)])  # twelve blocks, each on the table: fits
    with pytest.raises(InputError, match="13 towers need more table slots than the table holds"):
        layout([[f"b{i}"] for i in range(13)])


def test_slots_stay_on_the_table_in_front_of_the_robot_and_apart():
    for radius, spacing in [(0.55, 0.144), (0.4, 0.104), (0.65, 0.144), (1.0, 0.144)]:
        slots = np.array(make_slots(radius, spacing))
        assert len(slots) > 0
        np.testing.assert_allclose(np.hypot(*slots.T), radius)
        assert np.all(slots[:, 0] >= 0.05) and np.all(slots[:, 0] <= 0.9)  # table: x -0.25..0.95
        assert np.all(np.abs(slots[:, 1]) <= 0.55)  # table: y within 0.6
        gaps = np.linalg.norm(slots[:, None] - slots[None], axis=-1) + np.eye(len(slots))
        assert gaps.min() >= spacing - 1e-9
    # centre-out: the first two straddle the x axis
    assert SLOTS[0][1] < 0 < SLOTS[1][1] and abs(SLOTS[0][1] + SLOTS[1][1]) < 1e-12
    assert make_slots(0.55, 1.2) == ()  # wider apart than the arc allows


def test_any_block_names_get_distinct_colours_in_natural_order():
    names = [f"b{i}" for i in range(1, 13)] + ["table", "hand", "x-1"]
    colours = cube_colours(names)
    assert [colours[f"b{i}"][0] for i in (1, 2, 8)] == ["red", "orange", "pink"]
    assert colours["b10"][0] not in {colours[f"b{i}"][0] for i in range(1, 10)}  # b10 after b9
    rgbs = np.array([rgb for _, rgb in colours.values()])
    gaps = np.linalg.norm(rgbs[:, None] - rgbs[None], axis=-1) + np.eye(len(rgbs))
    assert gaps.min() > 0.1, "two cubes share (nearly) a colour"
    scene = add_world(DiagramBuilder(), names)
    inspector = scene.scene_graph.model_inspector()
    from pydrake.geometry import Role

    for name, (_, rgb) in colours.items():
        frame = scene.plant.GetBodyFrameIdOrThrow(scene.cube_body(name).index())
        for role, get in [
            (Role.kIllustration, inspector.GetIllustrationProperties),
            (Role.kPerception, inspector.GetPerceptionProperties),
        ]:
            (gid,) = inspector.GetGeometries(frame, role)
            diffuse = get(gid).GetProperty("phong", "diffuse")
            np.testing.assert_allclose([diffuse.r(), diffuse.g(), diffuse.b()], rgb)


@pytest.mark.slow
def test_render_is_not_blank_and_shows_each_cube_colour():
    from cake_drake.world.render import Renderer

    rgba = Renderer(BLOCKS5, width=640, height=480).render(layout([list("cba"), list("ed")]))
    assert rgba.shape == (480, 640, 4)
    assert rgba[..., :3].std() > 10  # not a blank frame
    hsv = rgb_to_hsv(rgba[..., :3] / 255.0)
    rgb = {
        "red": (0.85, 0.12, 0.12),
        "orange": (0.95, 0.55, 0.05),
        "yellow": (0.95, 0.85, 0.1),
        "green": (0.15, 0.7, 0.2),
        "blue": (0.12, 0.3, 0.9),
    }
    for key in "abcde":
        name = cube_colours(BLOCKS5)[key][0]
        hue = rgb_to_hsv(np.array(rgb[name]))[0]
        dh = np.abs((hsv[..., 0] - hue + 0.5) % 1 - 0.5)
        pixels = int(((dh < 0.03) & (hsv[..., 1] > 0.5) & (hsv[..., 2] > 0.2)).sum())
        assert pixels > 50, f"cube {key} ({name}) not visible: {pixels} pixels"


def test_world_cli_bad_input_is_one_line(tmp_path):
    import subprocess
    import sys

    bad = tmp_path / "p.pddl"
    bad.write_text("(define (problem x) (:domain blocksworld) (:objects a) (:init (on a a)")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cake_drake.world",
            "--problem",
            str(bad),
            "--render",
            str(tmp_path / "x.png"),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "x.png").exists()


def test_twelve_blocks_lay_out_and_render_each_in_its_own_colour():
    """Every cube seen where it stands has its own colour (beyond the eight named ones),
    told apart from the eleven others by chromaticity (shading scales brightness)."""
    from cake_drake.world.render import EYE, TARGET, Renderer, look_at

    blocks = [f"b{i}" for i in range(1, 13)]
    width, height = 640, 480
    poses = layout([blocks[0:5], blocks[5:9], blocks[9:12]])
    image = Renderer(blocks, width, height).render(poses)[..., :3].astype(float)
    X_CW = look_at(EYE, TARGET).inverse()
    focal = (height / 2) / np.tan(np.radians(45.0) / 2)  # the renderer's 45 deg field of view
    colours = cube_colours(blocks)
    chroma = {b: np.array(rgb) / sum(rgb) for b, (_, rgb) in colours.items()}
    for b in blocks:
        p = X_CW @ poses[b].translation()
        u = int(round(focal * p[0] / p[2] + width / 2))
        v = int(round(focal * p[1] / p[2] + height / 2))
        seen = image[v - 1 : v + 2, u - 1 : u + 2].reshape(-1, 3).mean(axis=0)
        seen = seen / seen.sum()
        nearest = min(blocks, key=lambda o: np.linalg.norm(seen - chroma[o]))
        assert nearest == b, f"{b} ({colours[b][0]}) looks like {nearest} ({colours[nearest][0]})"


def test_png_files_are_read_back_exactly(tmp_path):
    """The picture's PNG writer (standard library only): any RGBA image round-trips."""
    import matplotlib.image

    from cake_drake.world.render import save_png

    rng = np.random.default_rng(3)
    rgba = rng.integers(0, 256, (37, 53, 4), dtype=np.uint8)
    rgba[:10] = (200, 30, 30, 255)  # a flat run too
    save_png(rgba, tmp_path / "x.png")
    back = matplotlib.image.imread(tmp_path / "x.png")
    np.testing.assert_array_equal((back * 255).round().astype(np.uint8), rgba)
    assert not list(tmp_path.glob("*.part"))
