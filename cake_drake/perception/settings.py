"""The scenario's ``perception:`` section: which estimator tells the cake where the cubes
are, through which cameras, and the depth sensor's noise (docs/perception.md)."""

import math
from dataclasses import dataclass, field

import numpy as np

from cake_drake import artifacts
from cake_drake.errors import InputError
from cake_drake.perception.learned import checkpoint_of, is_learned
from cake_drake.world.cameras import Camera, camera_pose, check_cameras
from cake_drake.world.scene import TABLE_HALF_WIDTH, TABLE_X

#: The estimators, by name: ``truth`` reads the simulator's own poses (today's run, bit
#: for bit); ``depth`` finds the cubes in the cameras' colour images and fits each to its
#: depth points; ``oracle`` fits the same way to the renderer's label image (ground-truth
#: segmentation: for finding which half of ``depth`` is wrong, never a result);
#: ``learned`` (or ``learned@DIR``) answers each cube's pose from the same points with a
#: network instead of the fit (:mod:`cake_drake.perception.learned`).
ESTIMATORS = ("truth", "depth", "oracle", "learned")
NOISE_MODELS = ("off", "axial")


@dataclass
class DepthNoise:
    """Axial depth noise, sigma = ``sigma_m + growth (z - 0.4 m)^2`` (Nguyen et al. 2012:
    1.2 mm at 0.4 m, 1.9 mm at 1 m), drawn from the run's seed."""

    model: str = "off"  # off | axial
    sigma_m: float = 0.0012  # m, at 0.4 m
    growth: float = 0.0019  # m per m^2 beyond 0.4 m


def default_cameras() -> list[Camera]:
    """Three depth cameras outside the arc of table slots, looking in at the robot: one
    in front, one at each front corner of the table. Every cube of a ten-high tower on
    any slot shows to at least two of them (the robot stands behind the cubes, not in
    front of them)."""
    target = [0.3, 0.0, 0.12]
    common = {"target": target, "width": 320, "height": 240, "fov_y_deg": 50.0, "depth": True}
    return [
        Camera(name="front", xyz=[1.3, 0.0, 0.75], **common),
        Camera(name="left", xyz=[0.95, 0.85, 0.7], **common),
        Camera(name="right", xyz=[0.95, -0.85, 0.7], **common),
    ]


@dataclass
class Perception:
    """Where the cake's knowledge of the cubes comes from."""

    estimator: str = "truth"  # truth | depth | oracle | learned | learned@DIR
    #: The perception cameras (empty: :func:`default_cameras`); each gives colour and depth.
    cameras: list[Camera] = field(default_factory=list)
    noise: DepthNoise = field(default_factory=DepthNoise)
    #: Hz: the cameras' frame rate. An estimate asked for within one frame of the last
    #: is that frame's (with its age); the world is rendered only when asked.
    rate_hz: float = 30.0
    #: Keep every cube's points of every frame with the truth beside them (the learned
    #: estimator's data: ``python -m cake_drake.record --frames``).
    keep_points: bool = False

    def views(self) -> "list[Camera]":
        """The cameras in use."""
        return list(self.cameras) or default_cameras()


def check_perception(p: Perception) -> None:
    """Refuse a ``perception:`` section that cannot work, before anything is built."""
    if p.estimator not in ESTIMATORS and not is_learned(p.estimator):
        raise InputError(
            f"perception.estimator {p.estimator!r}; choose one of: {', '.join(ESTIMATORS)}, "
            "learned@DIR"
        )
    if p.noise.model not in NOISE_MODELS:
        raise InputError(
            f"perception.noise.model {p.noise.model!r}; choose one of: {', '.join(NOISE_MODELS)}"
        )
    for name in ("sigma_m", "growth"):
        value = getattr(p.noise, name)
        if not (math.isfinite(value) and 0.0 <= value <= 0.05):
            raise InputError(f"perception.noise.{name} = {value!r} is outside 0 to 0.05 m")
    if not (math.isfinite(p.rate_hz) and 0.1 <= p.rate_hz <= 1000.0):
        raise InputError(f"perception.rate_hz = {p.rate_hz!r} is outside 0.1 to 1000 Hz")
    views = p.views()
    check_cameras(views, "perception.cameras")
    for i, c in enumerate(views):
        if c.attached_to == "world" and not sees_table(c):
            raise InputError(
                f"perception.cameras[{i}] ({c.name}): at {list(c.xyz)} it sees no part of "
                f"the table (x {TABLE_X[0]} to {TABLE_X[1]} m, y within "
                f"+-{TABLE_HALF_WIDTH} m, z = 0); turn it towards the table"
            )
    if is_learned(p.estimator):
        artifacts.check(checkpoint_of(p.estimator), "perception",
                        role="perception.estimator", cameras=views)  # fmt: skip


def sees_table(camera: Camera) -> bool:
    """Whether any point of a grid over the table top falls inside the camera's image."""
    xs = np.linspace(*TABLE_X, 25)
    ys = np.linspace(-TABLE_HALF_WIDTH, TABLE_HALF_WIDTH, 25)
    grid = np.array([[x, y, 0.0] for x in xs for y in ys])
    p_C = camera_pose(camera).inverse().multiply(grid.T).T
    ahead = (p_C[:, 2] > 0.01) & (p_C[:, 2] < 5.0)
    f = camera.height / (2 * math.tan(math.radians(camera.fov_y_deg) / 2))
    u = f * p_C[ahead, 0] / p_C[ahead, 2]
    v = f * p_C[ahead, 1] / p_C[ahead, 2]
    inside = (np.abs(u) <= camera.width / 2) & (np.abs(v) <= camera.height / 2)
    return bool(inside.any())
