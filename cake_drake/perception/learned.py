"""The learned eyes: a point network that answers a cube's centre and yaw from the depth
points the cameras saw on it, in place of the classical fit (no ICP after it).

The cameras' pixels of a cube (found by colour, back-projected through each camera: the
classical estimator's first two steps) are fused in the world frame; the network reads up
to :data:`POINTS` of them, each as its offset from the points' median (in half cube
sides) and the unit ray it was seen along, and every point votes for the cube's centre
and for its yaw (as ``cos 4 psi, sin 4 psi``: a cube's yaw is known modulo 90 degrees),
with a weight of its own: the answer is the votes' weighted mean.
Read in the world frame, the points do not say where a camera stood: a camera moved and
told is a camera the network has already seen.

A checkpoint is a folder: ``perception.json`` (kind, format, the architecture, the
cameras it was trained with) and ``weights.npz``, read by :func:`load` alone, which
checks both. Inference is NumPy's; training is :mod:`cake_drake.learning.training.perception`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from cake_drake.errors import InputError
from cake_drake.formats import WeightsFolder, check_format
from cake_drake.paths import PACKAGE, resolve_path
from cake_drake.perception.fit import HALF, MIN_INLIERS, REACH, Fit
from cake_drake.world.cameras import Camera

KIND = "cake_drake.perception"
FORMAT = 1
#: The shipped estimator, ``perception.estimator: learned``.
SHIPPED = PACKAGE + "perception/cubes"
PREFIX = "learned@"
#: Points a cube's estimate reads (a random draw in training, an even spread in a run).
POINTS = 256
#: Each point's features: its offset from the median (3, half sides), its ray (3).
FEATURES = 6
#: Each point's answer: its vote for the centre (3, half sides), cos 4 psi, sin 4 psi,
#: and its weight's logit (a softmax over the cube's points).
ANSWER = 6
#: A camera as the checkpoint remembers it: what must match the scenario's.
CAMERA_FIELDS = ("name", "width", "height", "fov_y_deg")


def weight_shapes(width: int) -> dict[str, tuple[int, ...]]:
    """The arrays of a network of ``width``: a shared per-point encoder (w1, w2), the
    max-pooled global feature joined to each point's own (w3), its vote (w4, w5)."""
    half = width // 2
    return {
        "w1": (FEATURES, half), "b1": (half,),
        "w2": (half, width), "b2": (width,),
        "w3": (half + width, width), "b3": (width,),
        "w4": (width, half), "b4": (half,),
        "w5": (half, ANSWER), "b5": (ANSWER,),
    }  # fmt: skip


def point_features(points: np.ndarray, rays: np.ndarray, rng=None):
    """The network's input for one cube: ``(features (POINTS, 6), median (3,), count)``,
    or None where fewer than :data:`~cake_drake.perception.fit.MIN_INLIERS` points lie
    within reach of their median. ``rng`` draws the points (training); without one they
    are spread evenly over the cube's points (a run: the same points give the same
    answer)."""
    median = np.median(points, axis=0)
    near = np.linalg.norm(points - median, axis=1) < REACH
    points, rays = points[near], rays[near]
    n = len(points)
    if n < MIN_INLIERS:
        return None
    if rng is not None:
        pick = rng.choice(n, POINTS, replace=n < POINTS)
    else:
        pick = np.linspace(0, n - 1, POINTS).round().astype(int)
    x = np.hstack([(points[pick] - median) / HALF, rays[pick]])
    return x.astype(np.float32), median, n


def vote(x: np.ndarray, answers: np.ndarray) -> tuple[np.ndarray, float, float]:
    """One cube's points' answers, weighed: the centre (half sides, from the median) and
    the yaw's ``cos 4 psi, sin 4 psi``."""
    logit = answers[:, 5] - answers[:, 5].max()
    w = np.exp(logit) / np.exp(logit).sum()
    centre = w @ (x[:, :3] + answers[:, :3])
    return centre, float(w @ answers[:, 3]), float(w @ answers[:, 4])


@dataclass(frozen=True)
class PoseNetwork:
    """A loaded, checked estimator: its folder, description and weights."""

    folder: Path
    config: dict
    weights: dict[str, np.ndarray]

    @property
    def cameras(self) -> list[dict]:
        return list(self.config["cameras"])

    def answer(self, x: np.ndarray) -> np.ndarray:
        """The votes of every point of a batch of cubes ``(B, POINTS, 6)`` ->
        ``(B, POINTS, 5)``."""
        w = self.weights
        h1 = np.maximum(x @ w["w1"] + w["b1"], 0.0)
        h2 = np.maximum(h1 @ w["w2"] + w["b2"], 0.0)
        # [h1, g] @ w3, with the global feature g's part computed once a cube, not a point
        half = h1.shape[-1]
        g = h2.max(axis=1, keepdims=True) @ w["w3"][half:] + w["b3"]
        h3 = np.maximum(h1 @ w["w3"][:half] + g, 0.0)
        h4 = np.maximum(h3 @ w["w4"] + w["b4"], 0.0)
        return h4 @ w["w5"] + w["b5"]

    def fit(self, points: np.ndarray, rays: np.ndarray, start: RigidTransform | None) -> Fit | None:
        """A cube's pose from its world points and their rays, level, its yaw the one of
        four nearest the start's (or the cube's bearing from the robot's base, as the
        classical fit's); None where too few points are near their median."""
        return self.fit_all({"": (points, rays, start)}).get("")

    def fit_all(self, cubes: dict) -> dict[str, Fit]:
        """:meth:`fit` of every cube of a frame (``name -> (points, rays, start)``), the
        network asked once for all of them; a cube with too few points is left out."""
        prepared = {n: (point_features(P, r), start) for n, (P, r, start) in cubes.items()}
        prepared = {n: (p, start) for n, (p, start) in prepared.items() if p is not None}
        if not prepared:
            return {}
        answers = self.answer(np.stack([p[0] for p, _ in prepared.values()]))
        fits = {}
        for (name, ((x, median, n), start)), a in zip(prepared.items(), answers, strict=True):
            centre, c4, s4 = vote(x, a)
            centre = median + HALF * centre
            yaw = math.atan2(s4, c4) / 4
            if start is not None:
                R = start.rotation().matrix()
                ref = math.atan2(R[1, 0], R[0, 0])
            else:
                ref = math.atan2(centre[1], centre[0])
            yaw += (math.pi / 2) * round((ref - yaw) / (math.pi / 2))
            fits[name] = Fit(RigidTransform(RotationMatrix.MakeZRotation(yaw), centre), n, 0.0)
        return fits


def _check_config(path: Path, cfg: dict) -> None:
    bad = READER.bad
    if cfg.get("kind") != KIND:
        raise bad(path, f"field 'kind' is {cfg.get('kind')!r:.60}, expected {KIND!r}")
    check_format(cfg, path, (FORMAT,))
    width = cfg.get("width")
    if type(width) is not int or not 2 <= width <= 1024 or width % 2:
        raise bad(path, f"field 'width' is {width!r:.40}; an even whole number 2 to 1024")
    cams = cfg.get("cameras")
    if not isinstance(cams, list) or not cams or not all(isinstance(c, dict) for c in cams):
        raise bad(path, "field 'cameras' must list the cameras it was trained with")
    for i, c in enumerate(cams):
        missing = [f for f in CAMERA_FIELDS if f not in c]
        if missing:
            raise bad(path, f"cameras[{i}] lacks {', '.join(missing)}")


#: The checked reader of an estimator's folder (:class:`cake_drake.formats.WeightsFolder`).
READER = WeightsFolder(
    "learned cube estimator", "perception.json", _check_config,
    lambda cfg: weight_shapes(cfg["width"]), np.float32,
)  # fmt: skip


def load(path: str | Path) -> PoseNetwork:
    """Read and check an estimator's folder; :class:`InputError` naming the file and field.
    ``perception.json`` must say it is a cube estimator of this format; ``weights.npz``
    must hold exactly its architecture's arrays, finite numbers, read by the project's
    checked reader (nothing unpickled)."""
    folder = Path(path)
    return _load(folder.resolve(), READER.digest(folder))


@lru_cache(maxsize=4)
def _load(folder: Path, digest: str) -> PoseNetwork:
    del digest  # the cache's key: the same bytes are the same checkpoint
    return PoseNetwork(folder, *READER.read(folder))


def check_folder(path: str | Path, cameras: list[Camera] | None = None) -> PoseNetwork:
    """:func:`load`, refused in one line where ``cameras`` (the scenario's) differ from
    those the network was trained with in their names, sizes or fields of view."""
    net = load(path)
    if cameras is not None:
        mine = [{f: getattr(c, f) for f in CAMERA_FIELDS} for c in cameras]
        theirs = [{f: c[f] for f in CAMERA_FIELDS} for c in net.cameras]
        if mine != theirs:
            said = ", ".join(f"{c['name']} {c['width']}x{c['height']} {c['fov_y_deg']} deg"
                             for c in theirs)  # fmt: skip
            raise InputError(
                f"{path}: trained with the cameras {said}; the scenario's "
                f"perception.cameras differ (names, sizes or fields of view): give it those"
            )
    return net


def describe(path: str | Path) -> str:
    net = load(path)
    frames = net.config.get("training", {}).get("samples", "?")
    return f"learned eyes ({Path(path).name}: a point network, {frames} sightings)"


def checkpoint_of(spec: str) -> Path:
    """The folder an estimator name names: ``learned`` the shipped one, ``learned@DIR`` DIR."""
    if spec == "learned":
        return resolve_path(SHIPPED)
    folder = spec[len(PREFIX) :] if spec.startswith(PREFIX) else ""
    if folder:
        return resolve_path(folder)
    raise InputError(f"perception.estimator {spec!r}: a learned one is 'learned' or 'learned@DIR'")


def is_learned(spec: str) -> bool:
    return spec == "learned" or spec.startswith(PREFIX)
