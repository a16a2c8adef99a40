"""The perception layer: the pixel convention, the estimator on rendered scenes of known
poses (a ten-high tower, a cube in the fingers, a cube gone from where it was seen), the
door (``truth`` builds nothing; every consumer reads the estimator), the summary, and
bad settings refused in one line before anything is simulated."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.framework import DiagramBuilder

from cake_drake.diagram import build_diagram
from cake_drake.errors import InputError
from cake_drake.perception.cloud import Intrinsics, back_project, segment
from cake_drake.perception.estimator import view_of
from cake_drake.perception.fit import closest_on_cube, fit_cube
from cake_drake.perception.settings import check_perception
from cake_drake.pipeline import check, run
from cake_drake.scenario import Knock, Scenario
from cake_drake.symbolic import parse_problem
from cake_drake.symbolic.pddl import load_domain
from cake_drake.world.cameras import Camera, add_cameras
from cake_drake.world.scene import CUBE_SIZE, Q_HOME, add_world, cube_colours, layout
from tests.helpers import ROOT

DOMAIN = ROOT / "models" / "pddl" / "blocksworld.pddl"


def _one_cube_points(camera: Camera, X_WB: RigidTransform, naive: bool = False):
    """The world points of one red cube at ``X_WB`` seen by ``camera`` (a world camera),
    back-projected with the renderer's convention (or the naive ``u - cx``)."""
    builder = DiagramBuilder()
    scene = add_world(builder, ["a"], initial_poses={"a": X_WB})
    sensors = add_cameras(builder, scene, [camera])
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    scene.plant.SetPositions(scene.plant.GetMyContextFromRoot(context), scene.arm, Q_HOME)
    sensor = sensors[camera.name]
    sc = sensor.GetMyContextFromRoot(context)
    rgb = sensor.color_image_output_port().Eval(sc).data[:, :, :3]
    depth = sensor.depth_image_32F_output_port().Eval(sc).data[:, :, 0]
    labels = segment(rgb, [np.array(cube_colours(["a"])["a"][1]) * 255])
    rows, cols = np.nonzero(labels == 0)
    intr = view_of(camera).intrinsics
    if naive:  # pixel u read at u, not at its centre
        intr = dataclasses.replace(intr, cx=intr.cx + 0.5, cy=intr.cy + 0.5)
    p_C = back_project(depth, intr, rows, cols)
    return view_of(camera).X_PC.multiply(p_C.T).T


def _off_surface(points: np.ndarray, X_WB: RigidTransform) -> np.ndarray:
    """Each point's distance to the surface of the cube at ``X_WB`` (m)."""
    p_B = X_WB.inverse().multiply(points.T).T
    q, _ = closest_on_cube(p_B)
    return np.linalg.norm(p_B - q, axis=1)


def test_the_pixel_convention_puts_a_known_cube_where_it_is():
    X = RigidTransform(RollPitchYaw(0, 0, 0.3), [0.45, 0.05, CUBE_SIZE / 2])
    camera = Camera(name="down", xyz=[0.75, -0.3, 0.6], target=[0.45, 0.05, 0.0],
                    width=320, height=240, fov_y_deg=45.0)  # fmt: skip
    points = _one_cube_points(camera, X)
    assert len(points) > 200
    # Every back-projected pixel lies on the known cube's faces, to a micrometre.
    assert _off_surface(points, X).max() < 1e-5
    top = points[points[:, 2] > CUBE_SIZE - 1e-4]
    assert np.linalg.norm(top[:, :2].mean(axis=0) - [0.45, 0.05]) < 2e-3  # the top face seen
    # Read at the pixel's corner instead (CameraInfo's principal point as the pixel's
    # centre), the same pixels stand off the faces: the test can tell the two apart.
    naive = _one_cube_points(camera, X, naive=True)
    assert np.sqrt(np.mean(_off_surface(naive, X) ** 2)) > 2e-4
    # Fitted from three faces, the cube is where it is, to a tenth of a millimetre.
    fit = fit_cube(points, np.array(camera.xyz))
    assert fit is not None and fit.inliers == len(points)
    assert np.linalg.norm(fit.X_WB.translation() - X.translation()) < 1e-4


def test_back_projection_drops_pixels_without_depth():
    intr = Intrinsics(4, 2, 100.0, 100.0, 1.5, 0.5)
    depth = np.array([[1.0, np.inf, 0.0, np.nan], [2.0, 2.0, 2.0, 2.0]], np.float32)
    rows, cols = np.nonzero(np.ones((2, 4), bool))
    p = back_project(depth, intr, rows, cols)
    assert len(p) == 5 and np.all(np.isfinite(p))
    assert np.allclose(p[0], [(0 + 0.5 - 1.5) / 100, (0 + 0.5 - 0.5) / 100, 1.0])


def _frame(blocks, poses, estimator="depth", fingers=0.04, q=Q_HOME, noise="off", **kw):
    """A built Diagram with the estimator, the world at ``poses``: (cake, root context)."""
    s = Scenario()
    s.perception.estimator = estimator
    s.perception.noise.model = noise
    text = _problem(blocks)
    problem = parse_problem(load_domain(DOMAIN), text, "test.pddl")
    cake = build_diagram(s, problem, poses, **kw)
    context = cake.diagram.CreateDefaultContext()
    pc = cake.scene.plant.GetMyMutableContextFromRoot(context)
    cake.scene.plant.SetPositions(pc, cake.scene.arm, q)
    cake.scene.plant.SetPositions(pc, cake.scene.hand, [fingers, fingers])
    return cake, context


def _problem(blocks) -> str:
    objs = " ".join(blocks)
    init = " ".join(f"(on-table {b}) (clear {b})" for b in blocks)
    return (f"(define (problem t) (:domain blocksworld) (:objects {objs}) "
            f"(:init (arm-empty) {init}) (:goal (and (on-table {blocks[0]}))))")  # fmt: skip


def _errors(cake, context):
    est = cake.estimator
    frame = est.estimate(est.GetMyContextFromRoot(context))
    pc = cake.scene.plant.GetMyContextFromRoot(context)
    out = {}
    for name, e in frame.cubes.items():
        truth = cake.scene.plant.EvalBodyPoseInWorld(pc, cake.scene.cube_body(name))
        if e.X_WB is None:
            out[name] = None
        else:
            out[name] = float(np.linalg.norm(e.X_WB.translation() - truth.translation()))
    return frame, out


def test_a_ten_high_tower_is_estimated_within_a_millimetre():
    blocks = [f"b{i}" for i in range(1, 11)]
    poses = layout([blocks[:8], blocks[8:]])
    cake, context = _frame(blocks, poses)
    frame, errors = _errors(cake, context)
    assert all(e is not None for e in errors.values()), frame.unseen()
    assert np.median(list(errors.values())) < 3e-4 and max(errors.values()) < 1e-3, errors
    assert all(e.seen_now and e.inliers >= 20 for e in frame.cubes.values())


def test_a_cube_in_the_fingers_is_estimated_and_moves_with_the_hand():
    builder_cake, context = _frame(["a", "b"], layout([["a"], ["b"]]), fingers=0.02)
    plant, scene = builder_cake.scene.plant, builder_cake.scene
    pc = plant.GetMyMutableContextFromRoot(context)
    X_WG = scene.grasp_frame.CalcPoseInWorld(pc)
    plant.SetFreeBodyPose(pc, scene.cube_body("a"), X_WG)  # between the fingers
    frame, errors = _errors(builder_cake, context)
    assert errors["a"] is not None and errors["a"] < 1.5e-3, errors
    # The hand moves on and the fingers hide the cube from every camera: it is carried
    # with the hand, said with its age.
    est = builder_cake.estimator
    belief = est.belief(est.GetMyContextFromRoot(context))
    assert belief.last["a"][3] is not None  # seen in the hand: its pose in the grasp frame
    context.SetTime(1.0)
    q = Q_HOME.copy()
    q[0] += 0.2
    plant.SetPositions(pc, scene.arm, q)
    X_WG2 = scene.grasp_frame.CalcPoseInWorld(pc)
    plant.SetFreeBodyPose(pc, scene.cube_body("a"), RigidTransform([0.3, 0.0, -1.0]))  # hidden
    frame2 = est.estimate(est.GetMyContextFromRoot(context))
    a = frame2.cubes["a"]
    assert not a.seen_now and a.seen_at == 0.0 and a.age(1.0) == 1.0
    assert np.linalg.norm(a.X_WB.translation() - X_WG2.translation()) < 2e-3


def test_a_cube_gone_from_where_it_was_seen_is_unknown_and_said_by_name():
    cake, context = _frame(["a", "b"], layout([["a"], ["b"]]))
    est = cake.estimator
    est.estimate(est.GetMyContextFromRoot(context))
    pc = cake.scene.plant.GetMyMutableContextFromRoot(context)
    cake.scene.plant.SetFreeBodyPose(pc, cake.scene.cube_body("b"), RigidTransform([3, 3, -1]))
    context.SetTime(4.2)
    frame = est.estimate(est.GetMyContextFromRoot(context))
    assert frame.cubes["b"].X_WB is None and frame.cubes["a"].X_WB is not None
    assert frame.unseen() == ["cube b not seen by any camera since 0.0 s"]
    poses = est.GetOutputPort("body_poses").Eval(est.GetMyContextFromRoot(context))
    assert np.isnan(poses[int(cake.scene.cube_body("b").index())].translation()).all()


def test_a_cube_no_camera_ever_saw_is_unknown_from_the_start():
    poses = layout([["a"], ["b"]])
    poses["b"] = RigidTransform([3.0, 3.0, CUBE_SIZE / 2])  # far off the table's cameras
    cake, context = _frame(["a", "b"], poses)
    frame, _ = _errors(cake, context)
    assert frame.unseen() == ["cube b not seen by any camera since the run began"]


def test_the_estimator_reads_no_pose_of_the_simulator():
    cake, _ = _frame(["a", "b"], layout([["a", "b"]]))
    inputs = [cake.estimator.get_input_port(i).get_name()
              for i in range(cake.estimator.num_input_ports())]  # fmt: skip
    assert all(n in ("arm_state", "hand_state") or n.startswith(("color_", "depth_"))
               for n in inputs), inputs  # fmt: skip
    # Every consumer of the world's poses reads the estimator's port, none the plant's.
    diagram = cake.diagram
    plant_port = cake.scene.plant.get_body_poses_output_port()
    readers = [
        (inp.get_system().get_name(), inp.get_name())
        for inp, out in diagram.connection_map().items()
        if out == (cake.scene.plant, plant_port.get_index())
    ]
    assert readers == [], readers


def test_truth_builds_no_estimator_and_no_camera():
    cake, _ = _frame(["a", "b"], layout([["a", "b"]]), estimator="truth")
    assert cake.estimator is None
    names = [cake.diagram.GetSystems()[i].get_name() for i in range(len(cake.diagram.GetSystems()))]
    assert not [n for n in names if n.startswith("perception")]


def test_the_oracle_fits_to_the_renderers_labels():
    cake, context = _frame(["a", "b", "c"], layout([["a", "b", "c"]]), estimator="oracle")
    frame, errors = _errors(cake, context)
    assert max(errors.values()) < 1e-3, errors


@pytest.mark.parametrize(
    "change, says",
    [
        (lambda p: setattr(p, "estimator", "lidar"), "choose one of: truth, depth, oracle"),
        (lambda p: setattr(p.noise, "sigma_m", -0.001), "perception.noise.sigma_m = -0.001"),
        (lambda p: setattr(p.noise, "model", "gauss"), "choose one of: off, axial"),
        (lambda p: setattr(p, "rate_hz", 0.0), "perception.rate_hz"),
        (
            lambda p: p.cameras.append(Camera(name="sky", xyz=[0, 0, 1], target=[0, 0, 2])),
            "sees no part of the table",
        ),
        (lambda p: p.cameras.append(Camera(name="tiny", width=0)), "each side 16 to 4096"),
    ],
)
def test_bad_perception_settings_are_refused_in_one_line(change, says):
    s = Scenario()
    change(s.perception)
    with pytest.raises(InputError, match=says.replace("+", r"\+").replace(".", r"\.")):
        check_perception(s.perception)
    with pytest.raises(InputError):
        check(s, write=False)


def test_the_command_refuses_an_unknown_estimator_before_simulating(tmp_path):
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "cake_drake.run", "--perception", "lidar", "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "truth, depth, oracle" in r.stderr
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.slow
def test_depth_runs_problem_5_and_writes_its_error_log(tmp_path):
    s = Scenario()
    s.perception.estimator = "depth"
    s.perception.noise.model = "axial"
    s.outputs.folder = str(tmp_path)
    result = run(s)
    assert result.success, result.message
    summary = json.loads((tmp_path / "summary.json").read_text())
    p = summary["perception"]
    assert p["estimator"] == "depth" and p["noise"] == "axial" and p["frames"] > 10
    assert p["position_mm"]["median"] < 1.0 and p["position_mm"]["p95"] < 2.5, p
    assert summary["layers"]["perception"]["kind"] == "classical"
    assert (tmp_path / "perception.png").stat().st_size > 10_000


@pytest.mark.slow
def test_the_monitor_sees_a_knocked_cube_from_the_cameras():
    s = Scenario(faults=[Knock("d", 1.0)])
    s.perception.estimator = "depth"
    result = run(s, write=False)
    assert result.success, result.message
    assert result.execution.monitoring["events"], "the monitor saw nothing"
    assert result.execution.perception["summary"]["position_mm"]["p95"] < 2.0
    assert math.isfinite(result.execution.perception["summary"]["position_mm"]["max"])


def test_settling_sets_a_hidden_topped_cube_on_its_support_and_leaves_a_held_one():
    from cake_drake.perception.fit import Fit, settle

    h = CUBE_SIZE / 2
    X = lambda x, z: RigidTransform([x, 0.0, z])  # noqa: E731
    fits = {
        "low": Fit(X(0.5, h + 0.003), 300, 0.0, top=0),  # a tower's bottom, 3 mm high
        "mid": Fit(X(0.5, 3 * h - 0.002), 300, 0.0, top=0),  # on it, 2 mm low
        "top": Fit(X(0.5, 5 * h + 0.0004), 300, 0.0, top=120),  # its top seen: measured
        "held": Fit(X(0.2, 0.15), 80, 0.0, top=0),  # in the air: rests on nothing
        "noisy": Fit(RigidTransform(RollPitchYaw(0.03, 0, 0.4), [-0.3, 0, h]), 90, 0.0, top=50),
        "fallen": Fit(RigidTransform(RollPitchYaw(0.3, 0, 0.4), [0.3, 0.3, h]), 90, 0.0, top=9),
    }
    out = settle(fits, {})
    level = RollPitchYaw(out["noisy"].X_WB.rotation()).vector()
    assert np.allclose(level, [0, 0, 0.4])  # resting, tilted by noise alone: level
    assert out["fallen"] is fits["fallen"]  # tilted further: as fitted
    assert out["low"].X_WB.translation()[2] == pytest.approx(h)
    assert out["mid"].X_WB.translation()[2] == pytest.approx(3 * h)
    assert out["top"].X_WB.translation()[2] == pytest.approx(5 * h + 0.0004)
    assert out["held"].X_WB.translation()[2] == pytest.approx(0.15)


def test_segmentation_finds_a_cube_by_chromaticity_in_light_and_shade():
    colours = [np.array(c) * 255 for _, c in cube_colours(["a", "b", "c"]).values()]
    image = np.full((6, 8, 3), [200, 190, 170], np.uint8)  # the table: not saturated
    image[1:3, 1:3] = colours[0] * 0.9  # a's face in the light
    image[3:5, 1:3] = colours[0] * 0.45  # its side in shade: the same chromaticity
    image[1:3, 5:7] = colours[2] * 0.8
    image[5, 7] = [8, 2, 2]  # too dark to say
    labels = segment(image, colours)
    assert (labels[1:5, 1:3] == 0).all() and (labels[1:3, 5:7] == 2).all()
    assert (labels == 1).sum() == 0 and labels[0, 0] == -1 and labels[5, 7] == -1


def test_a_runs_scenario_yaml_writes_out_the_cameras_it_used():
    from cake_drake.perception.settings import default_cameras
    from cake_drake.scenario import dump_scenario, parse_scenario

    s = Scenario()
    s.perception.estimator = "depth"
    again = parse_scenario(dump_scenario(s), "scenario.yaml")
    assert [c.name for c in again.perception.views()] == [c.name for c in default_cameras()]
    assert again.perception.cameras and not s.perception.cameras  # the caller's is untouched
    assert not parse_scenario(dump_scenario(Scenario()), "s.yaml").perception.cameras  # truth
