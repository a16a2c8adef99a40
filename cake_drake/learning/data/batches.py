"""Training batches from a recording read once: the data path under LeRobot's loop.

LeRobot's ``LeRobotDataset`` builds every sample row by row from its Arrow table and
decodes every camera's frames for every sample, even for a policy that reads no image
(about 2 ms a state sample and 20-35 ms with two cameras here, against about 0.1 ms of
the network's step: lerobot#2549, #2895). :class:`ColumnDataset` wraps the dataset that
LeRobot's ``lerobot_train.train`` makes and answers the same samples from columns held in
memory:

- every numeric column is read once into a NumPy array;
- a batch is gathered with index arrays (``__getitems__``, which torch's ``DataLoader``
  calls with the whole batch's indices);
- the observation history and action chunks follow LeRobot's ``delta_timestamps``
  exactly: query indices clamped to the episode, ``<key>_is_pad`` where they fall outside
  it;
- a camera is decoded (PyAV, every frame once, kept as uint8) only when the policy reads
  it, and handed out as LeRobot does: float32 in [0, 1], channels first, through the
  dataset's image transforms;
- for a learned skill (a policy that reads ``observation.skill``) the episodes are cut
  into per-action segments (where ``ground_action`` changes): its history and chunks stop
  at its action's bounds, padded as at an episode's;
- a policy that sees reads ``observation.goal``: the goal's numbers of
  ``observation.environment_state`` without the cubes' poses.

Everything else - the metadata, the sampler's episode bounds, the policy, processors,
optimiser, scheduler and checkpoints - stays LeRobot's: :func:`fast_batches` swaps the
dataset ``lerobot_train`` makes for this one while it trains.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch

from cake_drake.policy.observations import GOAL_START

#: lerobot's own per-frame columns, always handed out.
INDEX_KEYS = ("timestamp", "frame_index", "episode_index", "index", "task_index")
#: A learned skill's input, and the column that says which ground action a frame is in.
SKILL, GROUND = "observation.skill", "ground_action"
#: The recording's column a learned skill reads as ``observation.skill``.
SKILL_COLUMN = "skill"
#: The goal alone (no pose), read by a policy that sees, and where it comes from.
GOAL, ENV_STATE = "observation.goal", "observation.environment_state"


def _segments(index: np.ndarray, episode: np.ndarray, ground: np.ndarray):
    """Each row's segment bounds (absolute frame indices, end exclusive): the run of frames
    of one episode under one ground action. A learned skill's history and action chunk
    stop where its action does, padded there as at an episode's end."""
    ground = np.asarray(ground).reshape(len(index), -1)
    new = np.ones(len(index), bool)
    new[1:] = (episode[1:] != episode[:-1]) | np.any(ground[1:] != ground[:-1], axis=1)
    new[1:] |= index[1:] != index[:-1] + 1
    first = np.flatnonzero(new)
    lengths = np.diff(np.r_[first, len(index)])
    start = np.repeat(index[first], lengths)
    return start, start + np.repeat(lengths, lengths)


def decode_all(path: Path) -> np.ndarray:
    """Every frame of the video at ``path``, in order, as uint8 (frames, H, W, 3): PyAV's
    own FFmpeg, as LeRobot's ``pyav`` backend decodes it."""
    import av  # PyAV (lerobot's, with FFmpeg): only where a video is decoded

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        # Into one array sized from the stream's frame count (no second copy), grown only
        # where a container does not say how many frames it holds.
        size = (stream.codec_context.height, stream.codec_context.width, 3)
        out = np.empty((max(int(stream.frames or 0), 0), *size), np.uint8)
        n = 0
        for frame in container.decode(stream):
            if n == len(out):
                out = np.concatenate([out, np.empty((max(64, n), *size), np.uint8)])
            out[n] = frame.to_ndarray(format="rgb24")
            n += 1
    return out[:n] if n < len(out) else out


def _arrow_table(hf_dataset):
    """The Arrow table behind a Hugging Face dataset, its rows in the dataset's order."""
    table = hf_dataset.data.table
    indices = getattr(hf_dataset, "_indices", None)
    if indices is not None:  # a selection of rows: take them
        table = table.take(indices.column(0))
    return table


def _column(table, key: str) -> np.ndarray:
    """Column ``key`` of an Arrow table as one NumPy array, read column-wise: (rows,) for
    a number, (rows, n) for a list of n. (The datasets library's own column reads format
    it row by row: about a second per 10,000 rows.)"""
    import pyarrow as pa  # a third of a second: only where a column is read

    column = table.column(key).combine_chunks()
    if (
        pa.types.is_list(column.type)
        or pa.types.is_large_list(column.type)
        or (pa.types.is_fixed_size_list(column.type))
    ):
        values = column.flatten().to_numpy(zero_copy_only=False)
        return np.ascontiguousarray(values.reshape(len(column), -1))
    return np.ascontiguousarray(column.to_numpy(zero_copy_only=False))


def _reader(base):
    """Where ``base`` keeps its ``delta_indices``: its reader (LeRobot 0.6), or itself."""
    reader = getattr(base, "reader", None)
    return reader if reader is not None and hasattr(reader, "delta_indices") else base


class ColumnDataset(torch.utils.data.Dataset):
    """``base`` (a ``LeRobotDataset``, its ``delta_timestamps`` set) answered from memory;
    ``keys``: the features the policy reads (cameras not among them are never decoded;
    ``None`` reads every camera). Any other attribute is ``base``'s."""

    def __init__(self, base, keys: Iterable[str] | None = None) -> None:
        self.base = base
        self.seconds = 0.0  # spent answering batches (__getitems__), for train's phases
        meta = base.meta
        table = base.hf_dataset.with_format("numpy")
        videos = set(meta.video_keys)
        wanted = None if keys is None else set(keys)
        arrow = _arrow_table(base.hf_dataset)
        self.columns: dict[str, np.ndarray] = {}
        for key, feature in meta.features.items():
            if key in videos or feature.get("dtype") in ("image", "string", "language"):
                continue
            if key in table.column_names:
                self.columns[key] = _column(arrow, key)
        index = self.columns["index"].astype(np.int64)
        # Absolute frame index -> row (the dataset may hold only some episodes).
        self._row_of = np.full(int(index.max()) + 1 if len(index) else 0, -1, np.int64)
        self._row_of[index] = np.arange(len(index))
        episodes = meta.episodes
        starts = np.asarray(episodes["dataset_from_index"], np.int64)
        ends = np.asarray(episodes["dataset_to_index"], np.int64)
        episode = self.columns["episode_index"].astype(np.int64)
        self._start, self._end = starts[episode], ends[episode]
        if wanted is not None and SKILL in wanted and GROUND in self.columns:
            self._start, self._end = _segments(index, episode, self.columns[GROUND])
        deltas = _reader(base).delta_indices or {}
        self._deltas = {k: np.asarray(v, np.int64) for k, v in deltas.items()}
        if wanted is not None and SKILL in wanted and SKILL_COLUMN in self.columns:
            self._derived_input(meta, SKILL, self.columns.pop(SKILL_COLUMN))
        if wanted is not None and GOAL in wanted and ENV_STATE in self.columns:
            self._derived_input(meta, GOAL, self.columns[ENV_STATE][:, GOAL_START:])
        self._tasks = [str(name) for name in meta.tasks.index]
        self.frames: dict[str, np.ndarray] = {}
        self._frame_of: dict[str, np.ndarray] = {}
        for key in sorted(videos):
            if wanted is not None and key not in wanted:
                continue
            self._load_video(key, episode)

    def _derived_input(self, meta, key: str, column: np.ndarray) -> None:
        """``column`` handed out as the input ``key`` (the recording's ``skill`` as
        ``observation.skill``, the goal as ``observation.goal``): an observation's history
        (``observation.state``'s deltas) and its statistics in the dataset's, which the
        policy standardises with."""
        column = np.ascontiguousarray(column)
        self.columns[key] = column
        if "observation.state" in self._deltas:
            self._deltas[key] = self._deltas["observation.state"]
        stats = getattr(meta, "stats", None)
        if isinstance(stats, dict) and key not in stats:
            stats[key] = {
                "mean": column.mean(axis=0), "std": column.std(axis=0),
                "min": column.min(axis=0), "max": column.max(axis=0),
            }  # fmt: skip

    def _load_video(self, key: str, episode: np.ndarray) -> None:
        """Decode camera ``key``'s files once; each row's frame number in ``self.frames``."""
        meta, fps = self.base.meta, self.base.meta.fps
        chunks, frame_of = [], np.zeros(len(episode), np.int64)
        offsets: dict[Path, int] = {}
        total = 0
        timestamps = self.columns["timestamp"].astype(np.float64)
        for ep in np.unique(episode):
            path = self.base.root / meta.get_video_file_path(int(ep), key)
            if path not in offsets:
                decoded = decode_all(path)
                offsets[path] = total
                chunks.append(decoded)
                total += len(decoded)
            start = float(meta.episodes[int(ep)][f"videos/{key}/from_timestamp"])
            rows = np.flatnonzero(episode == ep)
            frame_of[rows] = offsets[path] + np.rint((start + timestamps[rows]) * fps).astype(
                np.int64
            )
        self.frames[key] = np.concatenate(chunks) if len(chunks) > 1 else chunks[0]
        if frame_of.max(initial=0) >= len(self.frames[key]):
            raise ValueError(f"{key}: the video holds fewer frames than the recording's rows")
        self._frame_of[key] = frame_of

    def __len__(self) -> int:
        return len(self._start)

    def __getattr__(self, name: str):
        if name == "base":  # not yet set (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.base, name)

    def gather(self, rows: np.ndarray) -> dict[str, torch.Tensor]:
        """The batch of ``rows`` (relative indices), stacked: each key (B, ...) as
        LeRobot's samples would be after collation, without the tasks' strings."""
        rows = np.asarray(rows, np.int64)
        out: dict[str, torch.Tensor] = {}
        query: dict[str, np.ndarray] = {}
        absolute = self.columns["index"][rows].astype(np.int64)
        start, end = self._start[rows, None], self._end[rows, None]
        for key, deltas in self._deltas.items():
            wanted = absolute[:, None] + deltas
            query[key] = self._row_of[np.clip(wanted, start, end - 1)]
            out[f"{key}_is_pad"] = torch.from_numpy((wanted < start) | (wanted >= end))
        for key, column in self.columns.items():
            picked = column[query[key]] if key in query else column[rows]
            out[key] = torch.from_numpy(np.ascontiguousarray(picked))
        for key, frames in self.frames.items():
            at = self._frame_of[key][query[key] if key in query else rows]
            if at.ndim == 2 and at.shape[1] == 1:  # LeRobot squeezes a one-frame query
                at = at[:, 0]
            pixels = torch.from_numpy(frames[at])  # (B[, T], H, W, 3) uint8
            out[key] = pixels.movedim(-1, -3).float().div_(255.0)
        return out

    def __getitems__(self, indices) -> list[dict]:
        """The samples of ``indices``, one dict each, as ``LeRobotDataset.__getitem__``
        answers them (torch's ``DataLoader`` calls this with a whole batch)."""
        t0 = time.perf_counter()
        rows = np.asarray(indices, np.int64)
        batch = self.gather(rows)
        transforms = getattr(self.base, "image_transforms", None)
        task_index = self.columns["task_index"][rows]
        items = []
        for i in range(len(rows)):
            item = {key: value[i] for key, value in batch.items()}
            if transforms is not None:
                for key in self.frames:
                    item[key] = transforms(item[key])
            item["task"] = self._tasks[int(task_index[i])]
            items.append(item)
        self.seconds += time.perf_counter() - t0
        return items

    def __getitem__(self, idx: int) -> dict:
        return self.__getitems__([int(idx)])[0]


@contextlib.contextmanager
def fast_batches(keys: Iterable[str] | None):
    """While inside, ``lerobot_train.train`` trains on :class:`ColumnDataset` over the
    dataset it makes (``keys``: the features the policy reads). Yields the training's
    phases, filled in as it runs (seconds): ``loading`` (the recording read into memory),
    ``batches`` (answering the loop's batches), ``network`` (LeRobot's ``update_policy``:
    forward, backward, optimiser) and ``checkpoint`` (its ``save_checkpoint``); the
    caller adds ``train``, the whole of LeRobot's loop (the rest of it is LeRobot's set-up
    and logging)."""
    import lerobot.scripts.lerobot_train as lerobot_train  # LeRobot's loop: seconds, an extra

    keys = None if keys is None else list(keys)
    phases = dict.fromkeys(("loading", "batches", "network", "checkpoint"), 0.0)
    made: list[ColumnDataset] = []

    def timed(name: str, function):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                phases[name] += time.perf_counter() - t0

        return call

    def make(cfg):
        train, held_out = originals["make_train_eval_datasets"](cfg)
        wrap = None if held_out is None else ColumnDataset(held_out, keys)
        made.append(ColumnDataset(train, keys))
        return made[-1], wrap

    originals = {
        name: getattr(lerobot_train, name)
        for name in ("make_train_eval_datasets", "update_policy", "save_checkpoint")
    }
    lerobot_train.make_train_eval_datasets = timed("loading", make)
    lerobot_train.update_policy = timed("network", originals["update_policy"])
    lerobot_train.save_checkpoint = timed("checkpoint", originals["save_checkpoint"])
    try:
        yield phases
    finally:
        for name, function in originals.items():
            setattr(lerobot_train, name, function)
        phases["batches"] = sum(d.seconds for d in made)
