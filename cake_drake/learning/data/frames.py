"""The learned eyes' data: every cube the perception cameras saw in whole runs, its depth
points and the rays they were seen along, labelled with its true pose at that moment.

A run of the classical cake from the cameras (``perception.estimator: depth`` with
``keep_points``) visits the scenes the estimator must read: towers built and unbuilt, the
hand and a held cube in view. Each run draws its scene: a generated problem of 3 to 10
cubes (half of them few, tall towers), the tasks' placement jitter, depth noise on half
the runs, and every camera moved by up to :data:`CAMERA_JITTER_M` and aimed up to as far
off (the estimator told where it is). Colour and light only reach the estimator's
segmentation, which is the classical one, so they are not drawn.

A dataset is a folder: ``frames.json`` (kind, format, the runs, the cameras, counts) and
``frames.npz`` (one row a sighting), read by :func:`read_frames` alone, which checks both.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from cake_drake.errors import CakeDrakeError, InputError
from cake_drake.formats import check_format, read_json_mapping, read_npz
from cake_drake.perception.fit import HALF
from cake_drake.perception.learned import FEATURES, POINTS, point_features

KIND = "cake_drake.frames"
FORMAT = 1
FILES = ("frames.json", "frames.npz")
#: The first seed a recording takes unless told (the estimator's development seeds; the
#: perception tables report on 500000 and up).
FRAMES_SEED = 600000
#: m: how far each camera is moved, and its aim moved, at most, in a run of the data.
CAMERA_JITTER_M = 0.01
#: The arrays of a dataset, one row a sighting.
ARRAYS = {
    "features": ("N", POINTS, FEATURES),  # the network's input (float16)
    "median": ("N", 3),  # m: the points' median, the features' origin
    "position": ("N", 3),  # m: the cube's true centre
    "yaw": ("N",),  # rad: its true yaw, modulo 90 degrees
    "tilt": ("N",),  # rad: its z axis off world up
    "points": ("N",),  # how many points it showed
    "run": ("N",),  # which run of frames.json
    "t": ("N",),  # s: when
}


def frame_scenario(seed: int):
    """A run of the data: its scene drawn from ``seed`` (see the module)."""
    from cake_drake.perception.settings import default_cameras
    from cake_drake.scenario import Generate, Scenario

    rng = np.random.default_rng(seed)
    s = Scenario()
    s.seed = seed
    s.outputs.render = False
    blocks = int(rng.integers(3, 11))
    s.task.generate = Generate(blocks=blocks, seed=seed, tall=bool(rng.random() < 0.5))
    s.task.problem = ""
    s.world.placement.xy, s.world.placement.yaw_deg = 0.02, 30.0
    s.perception.estimator = "depth"
    s.perception.keep_points = True
    s.perception.noise.model = "axial" if rng.random() < 0.5 else "off"
    cameras = default_cameras()
    for c in cameras:
        c.xyz = [float(v) for v in np.add(c.xyz, rng.uniform(-1, 1, 3) * CAMERA_JITTER_M)]
        c.target = [float(v) for v in np.add(c.target, rng.uniform(-1, 1, 3) * CAMERA_JITTER_M)]
    s.perception.cameras = cameras
    return s


def yaw_mod(R: np.ndarray) -> float:
    """A rotation's yaw, modulo 90 degrees, in [-45, 45)."""
    yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    return (yaw + np.pi / 4) % (np.pi / 2) - np.pi / 4


def run_frames(seed: int) -> dict:
    """One run's sightings (in a worker): the network's inputs and their labels."""
    from cake_drake.pipeline import run

    t0 = time.perf_counter()
    s = frame_scenario(seed)
    out = {"seed": seed, "blocks": s.task.generate.blocks, "tall": s.task.generate.tall,
           "noise": s.perception.noise.model, "success": False, "rows": []}  # fmt: skip
    try:
        result = run(s, write=False)
    except CakeDrakeError as e:
        out["message"] = str(e)
        return out
    out.update(success=result.success, message=result.message)
    rng = np.random.default_rng([seed, 1])
    for t, _, P, rays, p_true, R_true in result.execution.perception["samples"]:
        prepared = point_features(P, rays, rng)
        if prepared is None:
            continue
        x, median, n = prepared
        out["rows"].append((x.astype(np.float16), median, p_true, yaw_mod(R_true),
                            float(np.arccos(np.clip(R_true[2, 2], -1, 1))), n, t))  # fmt: skip
    out["cameras"] = [asdict(c) for c in s.perception.cameras]
    out["wall_s"] = time.perf_counter() - t0
    return out


def record_frames(out: Path, episodes: int, first_seed: int, workers: int, progress=print) -> dict:
    """Record ``episodes`` runs' sightings into the folder ``out`` (written whole)."""
    from cake_drake.learning.parallel import imap
    from cake_drake.outputs.files import OutputDir
    from cake_drake.perception.settings import default_cameras

    t0 = time.perf_counter()
    seeds = [first_seed + k for k in range(episodes)]
    with OutputDir(out, "record", FILES) as staged:
        runs, rows = [], []
        for k, done in enumerate(imap(run_frames, seeds, workers), 1):
            for row in done.pop("rows"):
                rows.append((len(runs), *row))
            runs.append(done)
            progress(f"run {k}/{episodes} (seed {done['seed']}, {done['blocks']} cubes): "
                     f"{len(rows)} sightings so far")  # fmt: skip
        if not rows:
            raise InputError(f"{out}: no run saw a cube; nothing to record")
        cols = list(zip(*rows, strict=True))
        arrays = {
            "run": np.array(cols[0], np.int32),
            "features": np.stack(cols[1]),
            "median": np.array(cols[2], np.float32),
            "position": np.array(cols[3], np.float32),
            "yaw": np.array(cols[4], np.float32),
            "tilt": np.array(cols[5], np.float32),
            "points": np.array(cols[6], np.int32),
            "t": np.array(cols[7], np.float32),
        }
        np.savez_compressed(staged.path("frames.npz"), **arrays)
        meta = {
            "kind": KIND, "format": FORMAT, "samples": len(rows), "runs": runs,
            "seeds": [seeds[0], seeds[-1]], "points": POINTS, "half_side_m": HALF,
            "camera_jitter_m": CAMERA_JITTER_M,
            "cameras": [asdict(c) for c in default_cameras()],
            "minutes": round((time.perf_counter() - t0) / 60, 2),
        }  # fmt: skip
        staged.path("frames.json").write_text(json.dumps(meta, indent=1) + "\n")
        staged.commit()
    return meta


def read_frames(folder: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    """A dataset's description and arrays, checked: one line naming the file otherwise."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such frames dataset (a folder: frames.json, frames.npz)")
    meta_path = folder / "frames.json"
    if not meta_path.is_file():
        raise InputError(f"{folder}: no frames.json here: not a frames dataset "
                         "(python -m cake_drake.record --frames --out DIR)")  # fmt: skip
    meta = read_json_mapping(meta_path, "a frames dataset")
    if meta.get("kind") != KIND:
        raise InputError(
            f"{meta_path}: field 'kind' is {meta.get('kind')!r:.60}, expected {KIND!r}"
        )
    check_format(meta, meta_path, (FORMAT,))
    if meta.get("points") != POINTS:
        raise InputError(f"{meta_path}: field 'points' is {meta.get('points')!r:.20}; this "
                         f"version reads {POINTS} points a sighting")  # fmt: skip
    arrays = read_npz(folder / "frames.npz", "a frames dataset", ARRAYS, file_limit=2**31)
    for name, a in arrays.items():
        if not np.isfinite(a).all():
            raise InputError(f"{folder / 'frames.npz'}: array {name!r} holds NaN or "
                             "infinite values")  # fmt: skip
    if len(arrays["t"]) != meta.get("samples"):
        raise InputError(f"{meta_path}: says {meta.get('samples')!r:.20} samples; frames.npz "
                         f"holds {len(arrays['t'])}")  # fmt: skip
    return meta, arrays
