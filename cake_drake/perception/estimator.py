"""``CubeEstimator``: the world as the robot measures it, in the shape of the plant's
``body_poses``: the robot's bodies from its own joints, each cube from the cameras.

An estimate is made when a consumer asks (an action's start and end, a place measured,
a learned skill's period), never at every simulation step: the output is computed from
the images then, and Drake caches it for every consumer of that step. A frame asked for
within ``1 / rate_hz`` of the last is the last one (with its age).

What no camera sees now is carried from its last sighting, with its age: a cube between
closed fingers moves with the hand; any other stays where it was seen, as long as no
camera sees through the place it should be. A cube never seen, or seen through, is
unknown: its pose is NaN, and ``cube_estimates`` says since when it has not been seen.
The estimator reads no pose of the simulator's: its inputs are images and joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.systems.framework import BasicVector, LeafSystem
from pydrake.systems.sensors import CameraInfo, ImageDepth32F, ImageLabel16I, ImageRgba8U

from cake_drake.perception.cloud import Intrinsics, back_project, noisy_depth, segment
from cake_drake.perception.fit import HALF, INLIER_TOL, fit_cube, settle
from cake_drake.perception.settings import DepthNoise
from cake_drake.world.cameras import Camera, camera_pose
from cake_drake.world.facts import GRIP_RANGE, HELD_TOL
from cake_drake.world.scene import X_HAND_GRASP

#: m: a camera whose depth at a carried cube's centre lies this far behind it sees through
#: where the cube should be: the cube is not there.
SEE_THROUGH = 1.5 * HALF


@dataclass(frozen=True)
class CubeEstimate:
    """One cube as estimated: its pose (None: unknown), when it was last seen (None:
    never), the inliers of that sighting, and whether it is seen in this frame."""

    X_WB: RigidTransform | None
    seen_at: float | None
    inliers: int
    seen_now: bool

    def age(self, t: float) -> float | None:
        return None if self.seen_at is None else t - self.seen_at


@dataclass(frozen=True)
class Estimates:
    """A frame's estimates: the time, each cube's :class:`CubeEstimate`."""

    t: float
    cubes: dict[str, CubeEstimate]

    def unseen(self) -> list[str]:
        """One line per unknown cube: ``cube c not seen by any camera since 4.2 s``."""
        lines = []
        for name, e in sorted(self.cubes.items()):
            if e.X_WB is None:
                since = "the run began" if e.seen_at is None else f"{e.seen_at:.1f} s"
                lines.append(f"cube {name} not seen by any camera since {since}")
        return lines


@dataclass
class Belief:
    """What the estimator carries between frames (one per context, changed in place
    when a frame is taken): each cube's last sighting, the last frame, and every
    estimate made, for the error log."""

    last: dict[str, tuple[RigidTransform, float, int, RigidTransform | None]] = field(
        default_factory=dict
    )  # name -> (X_WB, t, inliers, X_GB when it was in the hand)
    frame: Estimates | None = None
    lost: dict[str, float | None] = field(default_factory=dict)  # unknown since
    log: list[tuple[float, str, RigidTransform, bool]] = field(default_factory=list)
    frames: int = 0
    #: Every cube's world points and their rays at each frame, (t, cube, points, rays):
    #: kept only where asked (the learned estimator's data), else None.
    points: list[tuple[float, str, np.ndarray, np.ndarray]] | None = None


@dataclass(frozen=True)
class View:
    """A perception camera as the estimator reads it."""

    camera: Camera
    intrinsics: Intrinsics
    X_PC: RigidTransform  # in the frame it is attached to (world, or the hand)


def view_of(camera: Camera) -> View:
    info = CameraInfo(camera.width, camera.height, math.radians(camera.fov_y_deg))
    return View(camera, Intrinsics.of(info), camera_pose(camera))


class CubeEstimator(LeafSystem):
    """Cube poses from colour and depth images, robot poses from the joints.

    .. pydrake_system::

        name: CubeEstimator
        input_ports:
        - arm_state
        - hand_state
        - color_<camera> (or label_<camera> for the oracle)
        - depth_<camera>
        output_ports:
        - body_poses
        - cube_estimates

    ``body_poses`` has the plant's own shape (one ``RigidTransform`` per body, in body
    index order), so every consumer of the plant's port reads this one unchanged.
    """

    def __init__(
        self,
        plant,
        arm,
        hand,
        cube_bodies: dict[str, int],
        colours: dict[str, tuple[float, float, float]],
        cameras: list[Camera],
        noise: DepthNoise,
        seed: int,
        rate_hz: float,
        labels: dict[str, int] | None = None,
        network=None,
        keep_points: bool = False,
    ) -> None:
        super().__init__()
        self._plant = plant
        self._arm, self._hand = arm, hand
        self._scratch = plant.CreateDefaultContext()  # the robot's kinematics only
        self._hand_body = plant.GetBodyByName("panda_hand", hand)
        self._cubes = dict(sorted(cube_bodies.items()))
        self._names = list(self._cubes)
        self._colours = np.array([colours[n] for n in self._names], float) * 255
        self._labels = labels  # name -> render label (the oracle)
        #: A :class:`~cake_drake.perception.learned.PoseNetwork` answers each cube's pose
        #: in place of the fit and the settling (None: the classical estimator).
        self._network = network
        self._rays = network is not None or keep_points
        self._views = [view_of(c) for c in cameras]
        self._noise = noise
        # Inliers within the noise-free tolerance, widened to 2.5 sigma of the noise at
        # 1.2 m (the far cubes) where there is noise.
        sigma = noise.sigma_m + noise.growth * 0.8**2 if noise.model == "axial" else 0.0
        self._tol = max(INLIER_TOL, 2.5 * sigma)
        self._seed = int(seed)
        self._period = 1.0 / rate_hz
        self._arm_port = self.DeclareVectorInputPort("arm_state", BasicVector(14))
        self._hand_port = self.DeclareVectorInputPort("hand_state", BasicVector(4))
        self._image_ports = []
        for v in self._views:
            w, h, name = v.camera.width, v.camera.height, v.camera.name
            if labels is None:
                image = self.DeclareAbstractInputPort(
                    f"color_{name}", AbstractValue.Make(ImageRgba8U(w, h))
                )
            else:
                image = self.DeclareAbstractInputPort(
                    f"label_{name}", AbstractValue.Make(ImageLabel16I(w, h))
                )
            depth = self.DeclareAbstractInputPort(
                f"depth_{name}", AbstractValue.Make(ImageDepth32F(w, h))
            )
            self._image_ports.append((image, depth))
        self._belief = self.DeclareAbstractState(
            AbstractValue.Make(Belief(points=[] if keep_points else None))
        )
        n_bodies = plant.num_bodies()
        self.DeclareAbstractOutputPort(
            "body_poses",
            lambda: AbstractValue.Make([RigidTransform()] * n_bodies),
            self._calc_poses,
        )
        self.DeclareAbstractOutputPort(
            "cube_estimates",
            lambda: AbstractValue.Make(Estimates(0.0, {})),
            lambda context, out: out.set_value(self.estimate(context)),
        )

    @property
    def cameras(self) -> list[Camera]:
        return [v.camera for v in self._views]

    def belief(self, context) -> Belief:
        return context.get_abstract_state(self._belief).get_value()

    # --- the robot, from its joints ------------------------------------------------------

    def _robot(self, context) -> tuple[list[RigidTransform], RigidTransform, float]:
        """Every body's pose with the robot's joints as measured (the cubes' entries are
        the plant's defaults, overwritten by the caller), the grasp frame, the fingers."""
        arm = self._arm_port.Eval(context)
        hand = self._hand_port.Eval(context)
        plant, scratch = self._plant, self._scratch
        plant.SetPositions(scratch, self._arm, arm[:7])
        plant.SetPositions(scratch, self._hand, hand[:2])
        poses = list(plant.get_body_poses_output_port().Eval(scratch))
        X_WG = poses[int(self._hand_body.index())] @ X_HAND_GRASP
        return poses, X_WG, float(hand[0])

    def _calc_poses(self, context, out) -> None:
        poses, _, _ = self._robot(context)
        frame = self.estimate(context)
        nan = RigidTransform([np.nan] * 3)
        for name, body in self._cubes.items():
            X = frame.cubes[name].X_WB
            poses[body] = nan if X is None else X
        out.set_value(poses)

    # --- the cubes, from the cameras -----------------------------------------------------

    def estimate(self, context) -> Estimates:
        """This moment's estimates: the last frame's if it is younger than one frame."""
        belief = self.belief(context)
        t = context.get_time()
        if belief.frame is not None and t - belief.frame.t < self._period - 1e-9:
            return belief.frame
        frame = self._take_frame(context, belief, t)
        belief.frame = frame
        belief.frames += 1
        return frame

    def _measure(self, context, X_WH: RigidTransform, t: float):
        """Per cube, its world points from every camera, the unit rays they were seen
        along and the cameras' places; and per camera, what a carried cube's visibility
        check needs (depth image, camera pose, intrinsics)."""
        points = {n: [] for n in self._names}
        rays = {n: [] for n in self._names}
        viewpoints = {n: [] for n in self._names}
        depths = []
        rng = np.random.default_rng([self._seed & 0xFFFFFFFF, round(t * 1e4)])
        for v, (image_port, depth_port) in zip(self._views, self._image_ports, strict=True):
            depth = np.asarray(depth_port.Eval(context).data)[:, :, 0]
            if self._noise.model == "axial":
                depth = noisy_depth(depth, self._noise.sigma_m, self._noise.growth, rng)
            image = np.asarray(image_port.Eval(context).data)
            if self._labels is None:
                labels = segment(image[:, :, :3], self._colours)
            else:
                labels = self._label_indices(image[:, :, 0])
            X_WC = v.X_PC if v.camera.attached_to == "world" else X_WH @ v.X_PC
            depths.append((depth, X_WC, v.intrinsics))
            rows, cols = np.nonzero(labels >= 0)
            if not len(rows):
                continue
            which = labels[rows, cols]
            for k in np.unique(which):
                pick = which == k
                p_C = back_project(depth, v.intrinsics, rows[pick], cols[pick])
                if len(p_C):
                    name = self._names[k]
                    p_W = X_WC.multiply(p_C.T).T
                    points[name].append(p_W)
                    viewpoints[name].append(X_WC.translation())
                    if self._rays:  # only the network and the data read them
                        ray = p_W - X_WC.translation()
                        rays[name].append(ray / np.linalg.norm(ray, axis=1, keepdims=True))
        return points, rays, viewpoints, depths

    def _label_indices(self, label: np.ndarray) -> np.ndarray:
        out = np.full(label.shape, -1, np.int32)
        for k, name in enumerate(self._names):
            out[label == self._labels[name]] = k
        return out

    def _take_frame(self, context, belief: Belief, t: float) -> Estimates:
        _, X_WG, fingers = self._robot(context)
        X_WH = X_WG @ X_HAND_GRASP.inverse()
        gripping = GRIP_RANGE[0] <= fingers <= GRIP_RANGE[1]
        points, rays, viewpoints, depths = self._measure(context, X_WH, t)
        cubes = {}
        fits, predictions, asked = {}, {}, {}
        for name in self._names:
            last = belief.last.get(name)
            if last is not None:
                X_last, _, _, X_GB = last
                predictions[name] = X_WG @ X_GB if (X_GB is not None and gripping) else X_last
            if points[name]:
                P = np.vstack(points[name])
                ray = np.vstack(rays[name]) if self._rays else None
                if belief.points is not None:
                    belief.points.append((t, name, P, ray))
                if self._network is not None:
                    asked[name] = (P, ray, predictions.get(name))
                    continue
                eye = np.mean(viewpoints[name], axis=0)
                fit = fit_cube(P, eye, predictions.get(name), self._tol)
                if fit is not None:
                    fits[name] = fit
        if self._network is not None:  # every cube of the frame in one question
            fits = self._network.fit_all(asked)
        else:
            fits = settle(fits, {n: X for n, X in predictions.items() if n not in belief.lost})
        for name in self._names:
            last, predicted = belief.last.get(name), predictions.get(name)
            fit = fits.get(name)
            if fit is not None:
                X = fit.X_WB
                held = gripping and np.linalg.norm(X.translation() - X_WG.translation()) < HELD_TOL
                X_GB = X_WG.inverse() @ X if held else None
                belief.last[name] = (X, t, fit.inliers, X_GB)
                belief.lost.pop(name, None)
                cubes[name] = CubeEstimate(X, t, fit.inliers, True)
                belief.log.append((t, name, X, True))
                continue
            if predicted is not None and name not in belief.lost:
                if not self._seen_through(predicted, depths):
                    _, seen_at, inliers, X_GB = last
                    if X_GB is not None and gripping:
                        belief.last[name] = (predicted, seen_at, inliers, X_GB)
                    cubes[name] = CubeEstimate(predicted, seen_at, inliers, False)
                    belief.log.append((t, name, predicted, False))
                    continue
                belief.lost[name] = last[1]
            since = belief.lost.setdefault(name, None if last is None else last[1])
            cubes[name] = CubeEstimate(None, since, 0, False)
        return Estimates(t, cubes)

    @staticmethod
    def _seen_through(X_WB: RigidTransform, depths) -> bool:
        """Whether a camera sees, at the cube's centre, something well behind it."""
        p_W = X_WB.translation()
        for depth, X_WC, intr in depths:
            p_C = X_WC.inverse().multiply(p_W)
            if p_C[2] <= 0.05:
                continue
            u, v = intr.project(p_C[None, :])[0]
            col, row = int(round(u)), int(round(v))
            if not (0 <= row < intr.height and 0 <= col < intr.width):
                continue
            z = float(depth[row, col])
            if np.isfinite(z) and z > p_C[2] + SEE_THROUGH:
                return True
        return False
