"""The cameras see what a policy needs: the whole table, and what the hand is about to grasp.

Rendered for real (VTK through EGL, headless): a camera put in the wrong place fails.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.framework import DiagramBuilder

from cake_drake.errors import InputError
from cake_drake.geometric.ik import DrakeIk, Kinematics
from cake_drake.pipeline import check
from cake_drake.scenario import Scenario, parse_scenario
from cake_drake.world.cameras import (
    Camera,
    add_cameras,
    default_cameras,
    grab,
    renderer_in_use,
    renderer_line,
)
from cake_drake.world.scene import (
    Q_HOME,
    X_HAND_GRASP,
    add_world,
    cube_colours,
    layout,
    make_slots,
    set_arm_positions,
)
from tests.helpers import ROOT

BLOCKS = [chr(ord("a") + i) for i in range(12)]


def _world(blocks, poses, cameras):
    builder = DiagramBuilder()
    scene = add_world(builder, blocks, initial_poses=poses)
    sensors = add_cameras(builder, scene, cameras)
    diagram = builder.Build()
    return scene, sensors, diagram, diagram.CreateDefaultContext()


def _seen(image: np.ndarray, rgb) -> int:
    """Pixels whose colour has the cube's hue (lit or shaded) - a count, not a match."""
    pixels = image.reshape(-1, 3).astype(float)
    bright = pixels.max(axis=1) > 40
    unit = pixels / np.maximum(np.linalg.norm(pixels, axis=1, keepdims=True), 1e-9)
    want = np.asarray(rgb, float) / np.linalg.norm(rgb)
    return int(np.sum(bright & (unit @ want > 0.995)))


def test_the_scene_camera_sees_a_cube_on_every_slot_of_the_table():
    poses = layout([[b] for b in BLOCKS], make_slots())  # twelve slots, one cube each
    cameras = default_cameras()
    _, sensors, _, context = _world(BLOCKS, poses, cameras)
    image = grab(sensors, cameras, context)["scene"]
    assert image.shape == (224, 224, 3) and image.dtype == np.uint8
    unseen = [b for b, (_, rgb) in cube_colours(BLOCKS).items() if _seen(image, rgb) < 8]
    assert not unseen, f"the scene camera misses the cubes {unseen}"


def test_a_scene_camera_looking_away_fails_the_same_check():
    poses = layout([[b] for b in BLOCKS], make_slots())
    away = [Camera(name="scene", xyz=[1.35, 0.0, 1.0], target=[2.5, 0.0, 1.0])]
    _, sensors, _, context = _world(BLOCKS, poses, away)
    image = grab(sensors, away, context)["scene"]
    assert all(_seen(image, rgb) < 8 for _, rgb in cube_colours(BLOCKS).values())


def test_the_wrist_camera_at_pre_grasp_has_the_target_cube_in_its_centre():
    blocks = ["a", "b", "c", "d", "e"]
    poses = layout([["c", "b", "a"], ["e", "d"]], make_slots()[:2])
    cameras = default_cameras()
    scene, sensors, _, context = _world(blocks, poses, cameras)
    kin = Kinematics()
    for cube in ("a", "d"):  # the top cube of each tower
        X_WB = poses[cube]
        yaw = X_WB.rotation().ToRollPitchYaw().yaw_angle()
        X_WG = RigidTransform(
            RotationMatrix(RollPitchYaw(np.pi, 0.0, yaw)), X_WB.translation() + [0, 0, 0.10]
        )  # 10 cm above the cube, pointing down: the pre-grasp pose
        q = DrakeIk(kin, 0).solve(X_WG, Q_HOME)
        assert q is not None
        set_arm_positions(scene, scene.plant.GetMyMutableContextFromRoot(context), q, 0.04)
        image = grab(sensors, cameras, context)["wrist"]
        centre = image[100:124, 100:124]
        rgb = cube_colours(blocks)[cube][1]
        assert _seen(centre, rgb) > 0.9 * centre.size / 3, cube
    assert X_HAND_GRASP.translation()[2] < default_cameras()[1].target[2]


def test_depth_is_there_when_asked_for_and_in_metres():
    cameras = [Camera(name="top", xyz=[0.4, 0.0, 1.0], target=[0.4, 0.0, 0.0], depth=True)]
    _, sensors, _, context = _world([], {}, cameras)
    images = grab(sensors, cameras, context)
    depth = images["top.depth"]
    assert depth.shape == (224, 224)
    assert 0.9 < float(depth[112, 112]) < 1.05  # the table's top, a metre below


@pytest.mark.parametrize(
    "yaml_text, words",
    [
        ("cameras: [{name: a}, {name: a}]", "two cameras named 'a'"),
        ("cameras: [{name: a, attached_to: elbow}]", "attached_to 'elbow'; choose one of"),
        ("cameras: [{name: a, width: 5}]", "5 x 224 pixels"),
        ("cameras: [{name: a, fov_y_deg: 200}]", "fov_y_deg 200"),
        ("cameras: [{name: a, xyz: [1, 2, 3], target: [1, 2, 3]}]", "stands at its own target"),
    ],
)
def test_a_camera_that_cannot_work_is_refused_before_anything_is_built(yaml_text, words):
    s = parse_scenario(yaml_text + "\n", "s.yaml")
    with pytest.raises(InputError, match=words.replace("(", r"\(")):
        check(s, write=False)


def test_a_run_without_cameras_builds_no_renderer():
    from cake_drake.diagram import build_diagram
    from cake_drake.pipeline import get_plan
    from cake_drake.symbolic import towers
    from cake_drake.symbolic.roles import blocksworld_view

    checked = check(Scenario(), write=False)
    view = blocksworld_view(checked.problem)
    initial = layout(towers(view.init), Scenario().world.slots_for(2))
    cake = build_diagram(Scenario(), checked.problem, initial, get_plan(checked).actions)
    assert cake.cameras == {} and not cake.scene.scene_graph.HasRenderer("vtk")


def test_a_run_with_cameras_writes_each_cameras_last_frame(tmp_path):
    import os
    import subprocess
    import sys

    root = ROOT
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--cameras", "--no-render", "--quiet",
         "--out", str(tmp_path / "o")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(root)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    for name in ("scene", "wrist"):
        data = (tmp_path / "o" / f"camera_{name}.png").read_bytes()
        assert data.startswith(b"\x89PNG") and len(data) > 2000
    assert "cameras:" in (tmp_path / "o" / "scenario.yaml").read_text()
    # The run names the GL implementation it rendered with: the one this process finds
    # (same machine, same libraries, same default device).
    import json

    renderer = json.loads((tmp_path / "o" / "summary.json").read_text())["renderer"]
    assert renderer == renderer_in_use()
    assert renderer["backend"] == "EGL" and renderer["vendor"] and renderer["device"]


#: The EGL vendor libraries glvnd loads, by the vendor string their displays report.
EGL_VENDOR_LIBRARIES = {"mesa": "libEGL_mesa.so", "nvidia": "libEGL_nvidia.so"}
#: Mesa's software rasteriser (llvmpipe), as a DRI driver or (Mesa 24 on) libgallium.
SOFTWARE_RASTERISER = ("swrast_dri.so", "libgallium")


def _loaded_libraries() -> set[str]:
    with open("/proc/self/maps") as f:
        return {line.split()[-1].rsplit("/", 1)[-1] for line in f if "/" in line}


def test_the_renderer_in_use_is_the_driver_this_process_loaded_for_it():
    cameras = [Camera(name="top", xyz=[0.4, 0.0, 1.0], target=[0.4, 0.0, 0.0])]
    _, sensors, _, context = _world([], {}, cameras)
    grab(sensors, cameras, context)
    renderer = renderer_in_use()
    assert renderer["backend"] == "EGL" and renderer["device"] and renderer["version"]
    loaded = _loaded_libraries()
    vendor = [k for k in EGL_VENDOR_LIBRARIES if k in renderer["vendor"].lower()]
    assert vendor, f"an EGL vendor of its own: {renderer['vendor']!r}"
    library = EGL_VENDOR_LIBRARIES[vendor[0]]
    assert any(name.startswith(library) for name in loaded), f"{library} is not loaded"
    if "llvmpipe" in renderer["device"]:  # no GPU: Mesa's software rasteriser renders
        assert vendor == ["mesa"]
        assert any(name.startswith(SOFTWARE_RASTERISER) for name in loaded), sorted(loaded)
    assert renderer_line().startswith(f"renderer: EGL, {renderer['vendor']}, {renderer['device']}")


def test_before_any_frame_the_renderer_is_found_by_rendering_one():
    """A thread that has rendered nothing has no EGL context: one small frame is rendered
    to ask VTK's own, and the answer is the one a camera's thread gets."""
    import threading

    cameras = [Camera(name="top", xyz=[0.4, 0.0, 1.0], target=[0.4, 0.0, 0.0])]
    _, sensors, _, context = _world([], {}, cameras)
    before = grab(sensors, cameras, context)["top"]
    seen = {}
    thread = threading.Thread(target=lambda: seen.update(renderer_in_use()))
    thread.start()
    thread.join()
    assert seen == renderer_in_use()
    assert np.array_equal(grab(sensors, cameras, context)["top"], before)  # still renders
