"""Episodes as a LeRobot dataset (format v3.0), written and read by ``lerobot`` itself.

A dataset holds, per frame (one control period, ``fps`` = the policy rate):
``observation.state`` (float32, 8: the seven joints in rad and the gripper's width in m),
``observation.environment_state`` (float32, 240: every cube's pose and the goal as numbers,
the layout of :mod:`cake_drake.policy.observations`),
``observation.images.<camera>`` (video, H x W x 3, H.264 through PyAV's own FFmpeg),
``action`` (float32, the control mode's: 8 for ``joint_position``, 7 for ``ee_delta``: the
demonstrator's label, also where noise or a learner changed what ran), ``actor`` (int64:
who acted, 0 the demonstrator, 1 a learner in DAgger's rollouts),
``skill`` (float32, 13) and ``ground_action`` (int64, 4): the demonstrator's ground
action under way, as a learned skill reads it (``observation.skill``'s numbers) and by
name (the layout of :mod:`cake_drake.policy.observations`; a recording is cut into
per-action segments where ``ground_action`` changes), and lerobot's own
``timestamp``, ``frame_index``, ``episode_index``, ``index`` and ``task_index``; the task
is the episode's English instruction. ``lerobot`` is an optional extra
(``pip install 'cake_drake[lerobot]'``, about 8 GB with torch); without it the commands
that need it are refused before any work.

Nothing is fetched: the dataset is written and read under a local ``root``, with the
Hugging Face hub set offline.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sys
import tempfile
import warnings
from collections.abc import Iterable
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.formats import read_json_mapping
from cake_drake.policy.observations import (
    ENVIRONMENT_STATE_SIZE,
    GOAL_COLUMNS,
    GROUND_ACTION_SIZE,
    MAX_CUBES,
    SKILL_SCHEMAS,
    SKILL_SIZE,
)

LEROBOT_PIP = "pip install 'cake_drake[lerobot]'  (lerobot 0.6, with torch: about 6 GB)"
#: The oldest LeRobot the learning commands are written and tested against.
LEROBOT_MIN = (0, 6)
#: The dataset's name inside its root (lerobot wants an owner/name).
REPO_ID = "cake_drake/stack"
STATE_NAMES = [f"joint_{i}" for i in range(1, 8)] + ["gripper_width"]
ENVIRONMENT_NAMES = [
    f"cube_{k}_{axis}" for k in range(MAX_CUBES) for axis in ("x", "y", "z", "qw", "qx", "qy", "qz")
] + [
    f"cube_{k}_on_{'table' if j == MAX_CUBES else f'cube_{j}'}"
    for k in range(MAX_CUBES)
    for j in range(GOAL_COLUMNS)
]
SKILL_NAMES = [f"is_{s.replace('-', '_')}" for s in SKILL_SCHEMAS] + [
    "cube_dx", "cube_dy", "cube_dz", "cube_dyaw",
    "target_dx", "target_dy", "target_dz", "target_dyaw", "transit_dz",
]  # fmt: skip
GROUND_NAMES = ["schema", "cube", "other", "plan_position"]
#: The ground action under way at a frame (see cake_drake.policy.observations): as a
#: learned skill reads it (``observation.skill``'s numbers), and by name. Not
#: ``observation.*`` keys, so LeRobot's own tools (``lerobot-train``) do not take them for
#: a whole-task policy's inputs; ``train --inputs skill`` reads ``skill`` as
#: ``observation.skill`` (cake_drake.learning.data.batches).
SKILL = "skill"
GROUND_ACTION = "ground_action"
ACTION_NAMES = {
    "joint_position": STATE_NAMES,
    "ee_delta": ["dx", "dy", "dz", "droll", "dpitch", "dyaw", "gripper"],
}


def _offline() -> None:
    """Never the hub, whatever the user's environment says: a recording is read from its
    folder alone. Set before huggingface_hub and datasets are imported (they read the
    variables then), and on their constants if they already are."""
    for name in ("HF_HUB_OFFLINE", "HF_DATASETS_OFFLINE"):
        os.environ[name] = "1"
    hub = sys.modules.get("huggingface_hub.constants")
    if hub is not None:
        hub.HF_HUB_OFFLINE = True
    config = sys.modules.get("datasets.config")
    if config is not None:
        config.HF_HUB_OFFLINE = config.HF_DATASETS_OFFLINE = True


def require_lerobot() -> None:
    """Refuse, in one line, where ``lerobot`` is not installed (with the line that installs
    it), where this Python is older than LeRobot 0.6 needs (3.12), or where the installed
    LeRobot is older than the one these commands are written against. Cheap (the
    packages' metadata and LeRobot's top package), so a check before any work can ask."""
    _offline()
    os.environ.setdefault("HF_DATASETS_DISABLE_PROGRESS_BARS", "1")
    if sys.version_info < (3, 12):
        raise InputError(
            f"the learning commands need LeRobot {'.'.join(map(str, LEROBOT_MIN))} or newer, "
            f"which needs Python 3.12 or newer; this is Python {sys.version.split()[0]}: "
            "make test makes a .venv with a newer Python where one is found"
        )
    try:
        found = version("lerobot")
    except PackageNotFoundError:
        raise InputError(f"LeRobot datasets need lerobot, which is not installed: "
                         f"{LEROBOT_PIP}") from None  # fmt: skip
    if tuple(int(p) for p in found.split(".")[:2] if p.isdigit()) < LEROBOT_MIN:
        raise InputError(f"lerobot {found} is installed; the learning commands need "
                         f"{'.'.join(map(str, LEROBOT_MIN))} or newer: {LEROBOT_PIP}")  # fmt: skip
    try:
        import lerobot  # noqa: F401 - the package alone (30 ms), not its datasets or policies
    except ImportError as e:
        raise InputError(f"lerobot {found} does not import ({e}): {LEROBOT_PIP}") from None


#: Who acted at a frame: 0 the demonstrator (or expert), 1 a learner.
ACTOR = "actor"


def features(control_mode: str, cameras) -> dict:
    """lerobot's feature table for episodes in ``control_mode`` with ``cameras``."""
    if control_mode not in ACTION_NAMES:
        raise InputError(
            f"control mode {control_mode!r} cannot be recorded; choose one of: "
            f"{', '.join(ACTION_NAMES)}"
        )
    table = {
        "observation.state": {"dtype": "float32", "shape": (8,), "names": STATE_NAMES},
        "observation.environment_state": {
            "dtype": "float32",
            "shape": (ENVIRONMENT_STATE_SIZE,),
            "names": ENVIRONMENT_NAMES,
        },
        "action": {
            "dtype": "float32",
            "shape": (len(ACTION_NAMES[control_mode]),),
            "names": ACTION_NAMES[control_mode],
        },
        ACTOR: {"dtype": "int64", "shape": (1,), "names": [ACTOR]},
        SKILL: {"dtype": "float32", "shape": (SKILL_SIZE,), "names": SKILL_NAMES},
        GROUND_ACTION: {"dtype": "int64", "shape": (GROUND_ACTION_SIZE,), "names": GROUND_NAMES},
    }
    for c in cameras:
        table[f"observation.images.{c.name}"] = {
            "dtype": "video",
            "shape": (c.height, c.width, 3),
            "names": ["height", "width", "channels"],
        }
    return table


@contextlib.contextmanager
def _quiet():
    """FFmpeg's encoder statistics and the datasets library's progress warnings are not the
    user's: the process's stderr goes to a file while lerobot works, shown only if it
    fails."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as sink, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        os.dup2(sink.fileno(), 2)
        try:
            yield
        except BaseException:
            os.dup2(saved, 2)
            sink.seek(0)
            sys.stderr.write(sink.read().decode(errors="replace")[-4000:])
            raise
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def write(root: Path, episodes: Iterable, fps: float, control_mode: str, cameras) -> int:
    """Write ``episodes`` (:class:`cake_drake.learning.rollout.Episode`, with frames) as a new
    dataset at ``root`` (which must not exist); the number of frames written."""
    require_lerobot()
    from lerobot.datasets.lerobot_dataset import LeRobotDataset  # lerobot: seconds, an extra

    with _quiet(), _no_image_embedding():
        return _write(LeRobotDataset, root, episodes, fps, control_mode, cameras)


@contextlib.contextmanager
def _no_image_embedding():
    """LeRobot's writer passes every saved episode, row by row, through ``embed_images``
    (about 2 ms a frame), which only changes features of dtype ``image``. Ours are state
    and video: the step is skipped while we write (half the writer's time), and LeRobot's
    writer is otherwise unchanged: the same tables and features, less the map's cache
    fingerprint in the schema's metadata (tests/learning/test_record.py checks it)."""
    from lerobot.datasets import dataset_writer  # lerobot: seconds, an extra

    embed = dataset_writer.embed_images
    dataset_writer.embed_images = lambda dataset: dataset
    try:
        yield
    finally:
        dataset_writer.embed_images = embed


def _write(LeRobotDataset, root, episodes, fps, control_mode, cameras) -> int:  # noqa: N803
    from lerobot.configs.video import RGBEncoderConfig  # lerobot: seconds, an extra

    dataset = LeRobotDataset.create(
        REPO_ID,
        fps=int(round(fps)),
        features=features(control_mode, cameras),
        root=root,
        robot_type="franka_panda",
        use_videos=bool(cameras),
        video_backend="pyav",
        # H.264 through PyAV's own FFmpeg: decoded everywhere (LeRobot's default is AV1).
        rgb_encoder=RGBEncoderConfig(vcodec="h264"),
    )
    frames = 0
    for ep in episodes:
        n = len(ep.actions)
        actors = ep.actors if ep.actors is not None else np.zeros(n, np.int64)
        skills = ep.skills if ep.skills is not None else np.zeros((n, SKILL_SIZE), np.float32)
        grounds = ep.grounds if ep.grounds is not None else np.full((n, GROUND_ACTION_SIZE), -1)
        for k in range(len(ep.actions)):
            frame = {
                "observation.state": ep.states[k],
                "observation.environment_state": ep.environment[k],
                "action": ep.actions[k],
                ACTOR: np.asarray([actors[k]], np.int64),
                SKILL: np.asarray(skills[k], np.float32),
                GROUND_ACTION: np.asarray(grounds[k], np.int64),
                "task": ep.task,
            }
            for name, video in ep.images.items():
                frame[f"observation.images.{name}"] = video[k]
            dataset.add_frame(frame)
        dataset.save_episode()
        frames += len(ep.actions)
    dataset.finalize()
    return frames


#: The metadata LeRobot reads before anything else; it would fetch a missing one.
META_FILES = ("meta/info.json", "meta/stats.json", "meta/tasks.parquet")


def read_info(root: Path) -> dict:
    """A recording's ``meta/info.json``, checked: a mapping with a positive ``fps``, the
    data (and video) path templates, and features whose shapes are lists of positive
    integers, the action's as long as its names. One line naming the field otherwise."""
    path = Path(root) / "meta" / "info.json"
    info = read_json_mapping(path, "a LeRobot dataset's metadata")
    fps = info.get("fps")
    if not (isinstance(fps, int | float) and not isinstance(fps, bool) and 0 < fps <= 1000):
        raise InputError(f"{path}: field 'fps' is {fps!r}; frames a second, more than 0")
    for key in ("data_path",) + (("video_path",) if info.get("video_path") else ()):
        if not isinstance(info.get(key), str):
            raise InputError(f"{path}: field {key!r} is missing or not a path template")
    features = info.get("features")
    if not isinstance(features, dict) or "action" not in features:
        raise InputError(f"{path}: field 'features' is missing, or has no 'action'")
    for name, f in features.items():
        shape = f.get("shape") if isinstance(f, dict) else None
        ok = isinstance(shape, list) and all(
            isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in shape
        )
        if not ok or not isinstance(f.get("dtype"), str):
            raise InputError(f"{path}: features.{name} needs a dtype and a shape (a list of "
                             f"positive integers), got {f!r:.80}")  # fmt: skip
    action = features["action"]
    names = action.get("names")
    if isinstance(names, list) and [len(names)] != action["shape"]:
        raise InputError(f"{path}: features.action has shape {action['shape']} but "
                         f"{len(names)} names ({', '.join(map(str, names))})")  # fmt: skip
    return info


def read_report(root: Path, required: bool = False) -> dict:
    """A recording's ``report.json`` (what cake_drake.record wrote), checked to be a
    mapping whose ``training`` part, if any, is one too; {} when absent and not
    ``required``."""
    path = Path(root) / "report.json"
    if not path.is_file():
        if required:
            raise InputError(f"{Path(root)}: no report.json; not a dataset written by "
                             "cake_drake.record")  # fmt: skip
        return {}
    report = read_json_mapping(path, "as cake_drake.record writes it")
    if not isinstance(report.get("training", {}), dict):
        raise InputError(f"{path}: field 'training' is not a mapping (the task's recipe)")
    return report


def check_recording(root: Path) -> dict:
    """The one check of a recording before LeRobot or anything else reads it: every file
    its metadata names is there (:func:`missing_files`), ``info.json`` is sound
    (:func:`read_info`), every table's footer reads (a truncated file is named), the
    action column is as wide as ``info.json`` says, and every video opens with a video
    stream and all its packets. Its ``info``."""
    import pyarrow.parquet as pq  # a third of a second: only where tables are read

    root = Path(root)
    if not root.is_dir():
        raise InputError(f"{root}: no such dataset folder")
    gone = missing_files(root)
    if gone:
        more = f" (and {len(gone) - 1} more)" if len(gone) > 1 else ""
        raise InputError(f"{root / gone[0]}: missing from the dataset{more}; a LeRobot "
                         "dataset is read from its own folder, never fetched")  # fmt: skip
    info = read_info(root)
    tables = sorted((root / "meta").glob("**/*.parquet")) + sorted(
        (root / "data").glob("chunk-*/file-*.parquet")
    )
    for table in tables:
        try:
            pq.read_metadata(table)
        except Exception as e:  # noqa: BLE001 - whatever pyarrow says of a damaged file
            raise InputError(
                f"{table}: unreadable table ({str(e)[:80]}); the recording is damaged "
                "(record it again, or restore the file)"
            ) from None
    data = sorted((root / "data").glob("chunk-*/file-*.parquet"))
    if data:
        try:
            column = pq.ParquetFile(data[0]).read_row_group(0, columns=["action"])["action"]
            width = len(column[0].as_py()) if len(column) else None
        except Exception as e:  # noqa: BLE001
            raise InputError(f"{data[0]}: unreadable table ({str(e)[:80]})") from None
        want = info["features"]["action"]["shape"][0]
        if width is not None and width != want:
            raise InputError(
                f"{root / 'meta' / 'info.json'}: features.action has shape [{want}], but "
                f"{data[0].name}'s actions hold {width} numbers"
            )
    for video in sorted((root / "videos").glob("**/*.mp4")):
        _check_video(video)
    return info


def _check_video(path: Path) -> None:
    """A video opens, has a video stream, and every packet it says it holds is there."""
    import av  # PyAV (lerobot's, with FFmpeg): only where a video is read

    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                raise ValueError("no video stream")
            stream = container.streams.video[0]
            packets = sum(1 for p in container.demux(stream) if p.size)
            if stream.frames and packets < stream.frames:
                raise ValueError(f"{packets} of its {stream.frames} frames are there")
    except (av.FFmpegError, ValueError, OSError) as e:
        raise InputError(f"{path}: unreadable video ({str(e)[:80]}); the recording is "
                         "damaged (record it again, or restore the file)") from None  # fmt: skip


def content_digest(root: Path) -> str:
    """A digest of a recording's tables' bytes (names and contents): what its cached
    Arrow copy is keyed on, so a file rewritten in place, times kept, is read anew."""
    h = hashlib.sha256()
    root = Path(root)
    for path in sorted((root / "data").glob("chunk-*/file-*.parquet")) + sorted(
        (root / "meta").glob("**/*.parquet")
    ):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()[:32]


@contextlib.contextmanager
def local_recording(root: Path):
    """While LeRobot reads the recording at ``root``: checked first
    (:func:`check_recording`), offline whatever the environment says, and the datasets
    library's Arrow cache keyed on the tables' content (its own key is a file's path and
    time). Yields the checked ``info``."""
    require_lerobot()
    info = check_recording(root)
    import datasets.config  # Hugging Face datasets (lerobot's): seconds, an extra

    _offline()
    before = datasets.config.HF_DATASETS_CACHE
    datasets.config.HF_DATASETS_CACHE = Path(before) / "cake_drake" / content_digest(root)
    try:
        yield info
    finally:
        datasets.config.HF_DATASETS_CACHE = before


def missing_files(root: Path) -> list[str]:
    """The files a LeRobot dataset at ``root`` names that are not there (relative paths):
    ``meta/info.json``, the episode tables, and every data and video file they point to.
    lerobot would fetch a missing one from the hub; a dataset here is read from its
    folder alone."""
    import pyarrow.parquet as pq  # a third of a second: only where tables are read

    root = Path(root)
    info_path = root / "meta" / "info.json"
    absent = [m for m in META_FILES if not (root / m).is_file()]
    if absent:
        return absent

    try:
        info = json.loads(info_path.read_text())
        data_path, video_path = info["data_path"], info.get("video_path")
        videos = [k for k, f in info["features"].items() if f.get("dtype") == "video"]
    except (ValueError, KeyError, TypeError, AttributeError):
        return ["meta/info.json (unreadable)"]
    tables = sorted((root / "meta" / "episodes").glob("chunk-*/file-*.parquet"))
    if not tables:
        return ["meta/episodes/chunk-000/file-000.parquet"]
    missing: list[str] = []
    for table in tables:
        try:
            rows = pq.read_table(table).to_pylist()
        except Exception:  # noqa: BLE001 - any unreadable table is named, whatever pyarrow says
            return [f"{table.relative_to(root)} (unreadable)"]
        for row in rows:
            wanted = [data_path.format(chunk_index=row["data/chunk_index"],
                                       file_index=row["data/file_index"])]  # fmt: skip
            for key in videos:
                wanted.append(
                    video_path.format(
                        video_key=key,
                        chunk_index=row[f"videos/{key}/chunk_index"],
                        file_index=row[f"videos/{key}/file_index"],
                    )
                )
            missing += [w for w in wanted if not (root / w).is_file() and w not in missing]
    return missing


def read(root: Path):
    """The dataset at ``root``, as lerobot reads it (decoding videos with PyAV), from its
    folder alone: a file it lacks is named (exit 2), never fetched."""
    with local_recording(root):
        from lerobot.datasets.lerobot_dataset import LeRobotDataset  # lerobot: seconds

        with _quiet():
            return LeRobotDataset(REPO_ID, root=root, video_backend="pyav")


def episode_actions(dataset, index: int) -> np.ndarray:
    """Episode ``index``'s actions, in order, from the dataset's own table."""
    table = dataset.hf_dataset.with_format("numpy")
    rows = np.flatnonzero(np.asarray(table["episode_index"]) == index)
    return np.stack([np.asarray(table[int(i)]["action"]) for i in rows])
