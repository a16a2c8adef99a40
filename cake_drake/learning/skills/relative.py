"""A skill that never sees the arm: its folder, its one checked loader, and how it acts.

The folder (``python -m cake_drake.train DATASET`` on a recording of the ``skills_relative``
task, or ``--inputs relative``) holds ``skill.json`` (what it reads and answers, and how it
was trained) and ``weights.npz`` (the network and its statistics). It reads only
``observation.relative`` (:func:`cake_drake.policy.observations.relative_vector`: the
action's cubes and target from the hand, and the gripper's width),
the last ``n_obs_steps`` of them, and answers:

- where the hand should be next, from the action's target (:func:`target_from_hand`:
  above the cube for a pick or an unstack; for a place, where the held cube is to rest,
  and once the fingers have let go of it, over the place at the transit height):
  dx dy dz (m, world axes; from format 3 on, answered on a scale fine near the target:
  :func:`compress`) and dyaw (rad). Added to the move onto the target, it is a
  move of the hand, turned into joints by the IK below
  (:class:`cake_drake.systems.skills.LearnedSkills`, ``ee_delta``), at whatever height
  and place the action is. Answered from the target rather than from the hand, a grasp
  or a place is as precise as the measured cube: the network says "at the cube", not
  "a little further";
- the gripper as a decision: one logit, the probability that the gripper should be
  closed. Above ``threshold`` it closes, below ``1 - threshold`` it opens, between the two
  it holds its last decision (:func:`decide`): a moving hand whose answer wavers near
  one half does not open and close in turn; a hand that has stopped takes the nearer
  side (``STOPPED_STEPS``), so that it does not stay over its place with the cube held.

Acting is NumPy alone (no torch at run time): the network is a few dense layers.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.formats import check_format, read_npz
from cake_drake.policy.observations import RELATIVE_SIZE
from cake_drake.policy.shield import FAR_ACROSS

#: What ``skill.json`` says a folder is.
KIND = "relative_skill"
#: The format a training writes: 4, which at run time reads a transit height below the
#: hand as the hand's own (:func:`floor_transit`) and a far target as a near one
#: (:func:`near_target`). From format 3 on, the moves are answered on a
#: scale that is fine near the target and coarse far from it (:func:`expand`,
#: ``move_scale_m``); format 2 answered them on one scale. From format 2 on, a place
#: whose fingers have let go of the cube answers from the point above the place at the
#: transit height; format 1 (the first trainings) answered it from the hand. Each is
#: read as it was trained.
FORMAT = 4
FORMATS = (1, 2, 3, 4)
INPUT = "observation.relative"
#: What the network answers, in this order, then the gripper's logit: the hand's next
#: target from the action's target (m, world axes; rad about z).
MOVES = ("dx", "dy", "dz", "dyaw")


def compress(move: np.ndarray, scale: float) -> np.ndarray:
    """A move of the hand (m) on the scale a format-3 network answers on,
    ``sign * log(1 + |move| / scale)``: a millimetre at the target counts as much there
    as 1 + |move| / scale millimetres further out (6 at 10 cm, on the trainer's 2 cm), so
    an error the size of the network's spread costs millimetres at the target, not
    centimetres. :func:`expand` is its inverse."""
    return np.sign(move) * np.log1p(np.abs(move) / scale)


def expand(answer: np.ndarray, scale: float) -> np.ndarray:
    """The move (m) a format-3 network's ``answer`` stands for (see :func:`compress`)."""
    return np.sign(answer) * scale * np.expm1(np.abs(answer))


#: ``observation.relative``'s gripper width, and its transit height from the hand.
WIDTH = 13
TRANSIT = 12


def floor_transit(x: np.ndarray) -> np.ndarray:
    """``observation.relative`` (..., 14), or several of them side by side (..., k * 14), as
    a format-4 skill's network reads them in a run: a transit height below the hand read
    as the hand's own (0). The transit height carries the held cube clear of every other
    tower, so it drops by a cube when the top of the tallest tower is the cube just
    taken; the hand starts the put-down or stack after that unstack above it, a scene
    the demonstrations show rarely (6,724 of 84,460 frames more than 5 mm above), and a
    network that read it as it was answered a move that stayed there, over its place.
    Read from the hand, a hand above its transit height is a hand at it, carrying its
    cube across, as every place does. The trainer learns from the frames as recorded:
    those frames' answers go down towards the transit height, and read as a hand at it
    they teach a crossing to dip (two trainings that did so built fewer towers). A copy."""
    out = np.array(x, np.float64)
    out[..., TRANSIT :: WIDTH + 1] = np.maximum(out[..., TRANSIT :: WIDTH + 1], 0.0)
    return out


#: m: fingers wider than this hold no cube (a cube is 0.04 across; open, 0.08).
LET_GO = 0.06


def target_from_hand(relative: np.ndarray, up_after_release: bool = True) -> np.ndarray:
    """The move of the hand that takes what the action moves onto its target, (..., 4):
    x y z and yaw, from ``observation.relative`` (..., 14). A pick or an unstack moves
    the hand: onto its target (above the cube at the transit height,
    ``observation.skill``'s 8-10), turned as the cube is (7). A place moves the held
    cube: onto where it is to rest (8-10 less the cube from the hand, 4-6), turned as the
    target says (11 less 7), however the cube sits in the fingers; once the fingers have
    let go of it (wider than ``LET_GO``), the hand goes up: its target is the point above
    the place at the transit height (8-9, and 12) — with ``up_after_release`` false, as
    format 1 had it, the cube that no longer moves with the hand (the answer then is a
    move from the hand, which a learner copies as a crawl)."""
    relative = np.asarray(relative)
    picking = (relative[..., 0] + relative[..., 1] > 0.5)[..., None]  # pick-up, unstack
    place_xyz = relative[..., 8:11] - relative[..., 4:7]
    if up_after_release:
        released = (relative[..., WIDTH] > LET_GO)[..., None]
        above = np.concatenate([relative[..., 8:10], relative[..., 12:13]], axis=-1)
        place_xyz = np.where(released, above, place_xyz)
    place_yaw = (relative[..., 11] - relative[..., 7] + np.pi / 4) % (np.pi / 2) - np.pi / 4
    xyz = np.where(picking, relative[..., 8:11], place_xyz)
    yaw = np.where(picking[..., 0], relative[..., 7], place_yaw)
    return np.concatenate([xyz, yaw[..., None]], axis=-1)


#: m: a held cube's place further below it than this reads, to a format-4 network, as
#: one this far below (:func:`near_target`).
DEEP = 0.2


def near_target(relative: np.ndarray, up_after_release: bool = True) -> np.ndarray:
    """``observation.relative`` (14) as a format-4 network reads it in a run, a copy: a
    target further across than ``FAR_ACROSS`` (the shield's far) read as if the hand were
    that far from it on the line to it, at the same height (what the fingers hold moves
    with the hand; the target and a cube still to be picked do not), so the network
    answers a heading near the target, where it is fine; a held cube's place further
    below it than ``DEEP`` read as ``DEEP`` below, within the demonstrations' depths."""
    out = np.array(relative, np.float64)
    to = target_from_hand(out, up_after_release)
    far = float(np.hypot(*to[:2]))
    if far > FAR_ACROSS:
        closer = to[:2] * (1.0 - FAR_ACROSS / far)
        out[8:10] -= closer
        if out[WIDTH] > LET_GO:  # the fingers hold no cube: it stays where it is
            out[4:6] -= closer
    holding_its_cube = out[2] + out[3] > 0.5 and out[WIDTH] <= LET_GO  # a place, not let go
    if holding_its_cube and -to[2] > DEEP:
        out[10] += -to[2] - DEEP
    return out


#: The gripper's decision: closed when its probability passes this, open below 1 - this.
THRESHOLD = 0.6
MAX_FILE_BYTES = 16 * 2**20
#: m the fingers' width may change in a step and count as still: while they move on a new
#: decision, the hand keeps to its target from before it (as the demonstrator's does).
FINGERS_STILL = 0.0005
#: Steps the hand waits for its fingers at most (1 s at 10 Hz).
MAX_WAIT = 10
#: m the hand's target may move in a step and the hand count as stopped there; after
#: ``STOPPED_STEPS`` such steps in a row (1 s at 10 Hz), the gripper's decision is the
#: nearer side of one half (:func:`decide`'s ``last`` None): the band between the two
#: thresholds keeps a moving hand's fingers from flickering, but a hand stopped with its
#: probability in the band would otherwise hold over its place until its budget ran out.
HAND_STILL = 0.0003
STOPPED_STEPS = 10


def gelu(x: np.ndarray) -> np.ndarray:
    """GELU, tanh form (the trainer's ``nn.GELU(approximate="tanh")``)."""
    return 0.5 * x * (1.0 + np.tanh(0.7978845608028654 * (x + 0.044715 * x**3)))


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-np.clip(x, -60.0, 60.0)))


def decide(p_closed: float, last: bool | None, threshold: float = THRESHOLD) -> bool:
    """The gripper's decision (True: closed) from the head's probability that it should
    be closed: closed above ``threshold``, open below ``1 - threshold``, and between the two
    the last decision held (``last``; None at an action's start: the nearer side)."""
    if p_closed >= threshold:
        return True
    if p_closed <= 1.0 - threshold:
        return False
    return p_closed >= 0.5 if last is None else last


def layer_shapes(meta: dict) -> list[tuple[int, int]]:
    """The dense layers' (inputs, outputs) that ``skill.json`` describes."""
    width = RELATIVE_SIZE * int(meta["n_obs_steps"])
    shapes = []
    for hidden in [*meta["hidden_dims"], len(MOVES) + 1]:
        shapes.append((width, int(hidden)))
        width = int(hidden)
    return shapes


def _read_meta(folder: Path) -> dict:
    path = folder / "skill.json"
    if path.stat().st_size > MAX_FILE_BYTES:
        raise InputError(f"{path}: over 16 MiB; a skill's description is a few lines")
    try:
        meta = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"{path}: not JSON ({e})") from None
    if not isinstance(meta, dict) or meta.get("kind") != KIND:
        said = meta.get("kind") if isinstance(meta, dict) else meta
        raise InputError(f"{path}: kind {said!r:.40}; a skill that never sees the arm says "
                         f"kind: {KIND}")  # fmt: skip
    check_format(meta, path, FORMATS)
    if meta.get("input") != INPUT or meta.get("input_size") != RELATIVE_SIZE:
        raise InputError(
            f"{path}: reads {meta.get('input')!r} of {meta.get('input_size')!r} numbers; this "
            f"cake_drake's skills read {INPUT} of {RELATIVE_SIZE} (train it again)"
        )
    steps, hidden = meta.get("n_obs_steps"), meta.get("hidden_dims")
    if not (isinstance(steps, int) and 1 <= steps <= 10):
        raise InputError(f"{path}: n_obs_steps {steps!r}; 1 to 10 observations")
    if not (isinstance(hidden, list) and hidden and all(isinstance(h, int) and 1 <= h <= 4096
                                                        for h in hidden)):  # fmt: skip
        raise InputError(f"{path}: hidden_dims {hidden!r:.40}; a list of layer widths, 1 to 4096")
    if meta.get("moves") != list(MOVES):
        raise InputError(f"{path}: moves {meta.get('moves')!r:.60}; a skill answers {list(MOVES)}")
    scale = meta.get("move_scale_m")
    if meta["format"] >= 3 and not (isinstance(scale, int | float) and 1e-4 <= scale <= 1.0):
        raise InputError(f"{path}: move_scale_m {scale!r:.24}; a skill of format 3 or later "
                         "answers its moves on a scale of 0.0001 to 1 m")  # fmt: skip
    gripper = meta.get("gripper")
    if not (isinstance(gripper, dict) and gripper.get("head") == "closed_logit"):
        raise InputError(
            f"{path}: no gripper head (gripper.head: closed_logit, one logit: the gripper "
            "as a decision); a skill that never sees the arm decides its gripper"
        )
    threshold = gripper.get("threshold", THRESHOLD)
    if not (isinstance(threshold, int | float) and 0.5 <= threshold < 1.0):
        raise InputError(f"{path}: gripper.threshold {threshold!r:.24}; from 0.5 to below 1")
    return meta


def check_folder(path: Path, **needs) -> Path:
    """Refuse, in one line, a folder that is no skill that never sees the arm, or whose
    weights do not fit its description (a gripper head missing or of another size, a
    layer of another width, numbers that are not finite). The folder."""
    folder = Path(path)
    _weights(folder, _read_meta(folder))
    return folder


def _weights(folder: Path, meta: dict) -> dict[str, np.ndarray]:
    shapes = layer_shapes(meta)
    width = RELATIVE_SIZE * int(meta["n_obs_steps"])
    expected = {"in_mean": (width,), "in_std": (width,), "move_mean": (len(MOVES),),
                "move_std": (len(MOVES),)}  # fmt: skip
    for k, (n_in, n_out) in enumerate(shapes):
        expected[f"w{k}"], expected[f"b{k}"] = (n_in, n_out), (n_out,)
    path = folder / "weights.npz"
    arrays = read_npz(path, "a skill's weights (skill.json says which)",
                      {name: (None,) * len(shape) for name, shape in expected.items()},
                      file_limit=MAX_FILE_BYTES * 4)  # fmt: skip
    last = f"w{len(shapes) - 1}"
    for name, shape in expected.items():
        got = tuple(arrays[name].shape)
        if got != shape:
            if name in (last, f"b{len(shapes) - 1}"):
                raise InputError(
                    f"{path}: the last layer answers {got[-1]} numbers; a skill answers "
                    f"{len(MOVES)} moves ({' '.join(MOVES)}) and its gripper head (1 logit): "
                    f"{len(MOVES) + 1}"
                )
            raise InputError(f"{path}: {name} has shape {got}; skill.json describes {shape}")
        if not np.all(np.isfinite(arrays[name])):
            raise InputError(f"{path}: {name} holds numbers that are not finite")
    return {k: np.asarray(v, np.float64) for k, v in arrays.items()}


class RelativeSkill:
    """The skill of a folder, as :class:`cake_drake.systems.skills.LearnedSkills` asks it:
    ``reset()`` at each new action, ``act(observation)`` -> 7 numbers of ``ee_delta`` (the
    move, no roll or pitch, and the gripper: 1 open, 0 closed)."""

    action_space = "ee_delta"
    #: It reads every yaw modulo a quarter turn, so the hand may take any quarter turn of
    #: its answer (:class:`cake_drake.systems.skills.LearnedSkills` keeps the wrist
    #: mid-range so).
    free_quarter_turns = True

    def __init__(self, path: str | Path, threshold: float | None = None) -> None:
        self.folder = Path(path)
        self.meta = _read_meta(self.folder)
        w = _weights(self.folder, self.meta)
        self.layers = [(w[f"w{k}"], w[f"b{k}"]) for k in range(len(layer_shapes(self.meta)))]
        self.in_mean, self.in_std = w["in_mean"], w["in_std"]
        self.move_mean, self.move_std = w["move_mean"], w["move_std"]
        self.n_obs = int(self.meta["n_obs_steps"])
        self.threshold = float(threshold or self.meta["gripper"].get("threshold", THRESHOLD))
        self.up_after_release = self.meta["format"] >= 2
        #: m: the scale of a format-3 skill's moves (None: answered as they are).
        self.move_scale = self.meta.get("move_scale_m") if self.meta["format"] >= 3 else None
        #: Format 4 reads a transit height below the hand, and a far target, as
        #: :func:`floor_transit` and :func:`near_target` say.
        self.format4 = self.meta["format"] >= 4
        self.reset()

    def reset(self) -> None:
        self._seen: list[np.ndarray] = []
        self._closed: bool | None = None
        self._width: float | None = None
        self._waited: int | None = None  # steps since the decision changed, while waiting
        self._last: np.ndarray | None = None  # the answer before it changed
        self._onto: np.ndarray | None = None  # the move onto the target, a step before
        self._stopped = 0  # steps in a row the hand has stayed where it was
        #: The gripper head's last probability that the gripper should be closed (None
        #: before the action's first answer): what the decision was made from.
        self.p_closed: float | None = None

    #: What the skill remembers between answers (:meth:`reset` sets it).
    MEMORY = ("_seen", "_closed", "_width", "_waited", "_last", "_onto", "_stopped", "p_closed")

    def memory(self) -> dict:
        """What it remembers of the action so far (a start pool saves it)."""
        return copy.deepcopy({name: getattr(self, name) for name in self.MEMORY})

    def restore(self, memory: dict) -> None:
        """Remember ``memory`` (:meth:`memory`'s), as if it had answered those periods."""
        if set(memory) != set(self.MEMORY):
            raise ValueError(f"a relative skill's memory holds {', '.join(self.MEMORY)}")
        for name, value in memory.items():
            setattr(self, name, list(value) if name == "_seen" else value)

    def forward(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The moves and the gripper's probability of closed for inputs ``x`` (B, n_obs *
        14), oldest observation first."""
        h = (np.asarray(x, np.float64) - self.in_mean) / self.in_std
        for w, b in self.layers[:-1]:
            h = gelu(h @ w + b)
        w, b = self.layers[-1]
        out = h @ w + b
        moves = self.move_mean + out[:, : len(MOVES)] * self.move_std
        if self.move_scale:
            moves[:, :3] = expand(moves[:, :3], self.move_scale)
        return moves, sigmoid(out[:, -1])

    def act(self, observation) -> np.ndarray:
        now = np.asarray(observation[INPUT], np.float64).reshape(RELATIVE_SIZE)
        read = near_target(floor_transit(now), self.up_after_release) if self.format4 else now
        if not self._seen:
            self._seen = [read] * self.n_obs
        self._seen = [*self._seen[1:], read]
        moves, p_closed = self.forward(np.concatenate(self._seen)[None])
        self.p_closed = float(p_closed[0])
        onto = target_from_hand(now, self.up_after_release)
        still = self._onto is not None and np.linalg.norm(onto[:3] - self._onto[:3]) < HAND_STILL
        self._stopped, self._onto = (self._stopped + 1 if still else 0), onto
        last = None if self._stopped >= STOPPED_STEPS else self._closed
        closed = decide(self.p_closed, last, self.threshold)
        width = float(now[WIDTH])
        if self._closed is not None and closed != self._closed:
            self._waited = 0
        elif self._waited is not None:
            self._waited += 1
            moving = self._width is not None and abs(width - self._width) > FINGERS_STILL
            if self._waited >= MAX_WAIT or (self._waited >= 2 and not moving):
                self._waited = None
        self._closed, self._width = closed, width
        if self._waited is None or self._last is None:
            self._last = moves[0]
        # While the fingers move on a new decision, the hand keeps to where it was going
        # before it (the cube it grasps, the place it lets go): no lift before the grip.
        # The hand's target, answered from the action's target, as a move from the hand.
        dx, dy, dz, dyaw = self._last + onto
        return np.array([dx, dy, dz, 0.0, 0.0, dyaw, 0.0 if self._closed else 1.0])


def describe(path: str | Path) -> str:
    """What the skill at ``path`` reads and answers, for a run's ``layers``."""
    _read_meta(Path(path))
    return (
        "imitation, reads the action from the hand (never the arm), answers hand moves "
        "with IK below and a gripper decision"
    )


def make(path: str | Path, **options) -> RelativeSkill:
    """The loader :mod:`cake_drake.artifacts` names for this kind."""
    return RelativeSkill(path)
