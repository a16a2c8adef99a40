"""Training a skill that never sees the arm (:mod:`cake_drake.learning.skills.relative`)
from a recording of the hand's moves (``ee_delta``, with ``skill`` and ``ground_action``).

The recording's frames are cut into per-action segments (where ``ground_action`` changes;
frames with no action under way are not a skill's). Each frame gives the network its
``observation.relative`` (the recording's ``skill`` numbers, the gripper's width from
``observation.state``) and the ones before it in its segment, and
two targets: the demonstrator's move of the hand (dx dy dz dyaw, standardised; an L1
loss, as the other policies') and whether its gripper was closed (a binary
cross-entropy on one logit: :func:`losses`). The recording's joints are never read.
Each batch is varied where the answer does not change (:func:`augment`: a cube held off
centre, the transit height in a final descent). Torch trains it on the CPU; the folder
is written through the output transaction.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.learning.skills import relative as rs
from cake_drake.policy.observations import SKILL_SIZE

#: What a training writes.
FILES = ("skill.json", "weights.npz")
#: The recording's action: dx dy dz droll dpitch dyaw gripper (1 open, 0 closed).
MOVE_COLUMNS = (0, 1, 2, 5)
GRIPPER_COLUMN = 6
#: Frames ahead (at the recording's 10 Hz: half a second) whose heading a frame learns.
LOOKAHEAD = 5
#: Frames ahead whose gripper command a frame learns (0.1 s).
GRIP_LOOKAHEAD = 1
#: m from where a motion ends at which the hand counts as arrived there.
ARRIVED = 0.003
#: m across from its target at which a hand counts as over it (its crossing done).
OVER = 0.003
#: How far :func:`augment` moves the hand about a held cube, at most (x, y, z in m; yaw
#: in rad).
GRASP_JITTER = np.array([0.004, 0.004, 0.012, 0.1])
#: How much :func:`augment` widens or narrows the fingers on a held cube, at most (m).
GRIP_JITTER = 0.002
#: How far :func:`augment` raises the transit height of a frame in a final descent, at
#: most (m); it lowers it down to ``TRANSIT_CLEAR`` above the hand.
TRANSIT_RAISE = 0.3
TRANSIT_CLEAR = 0.01
#: The share of a batch's frames :func:`augment` may vary.
AUGMENTED = 0.5
#: m: the scale the moves are learned on (``compress`` in
#: :mod:`cake_drake.learning.skills.relative`): a network that answers the move
#: itself, standardised over whole crossings (a spread of decimetres), answered a place's
#: last millimetres a few millimetres off, and held the cube over its place.
MOVE_SCALE = 0.02


def read_frames(root: Path) -> dict[str, np.ndarray]:
    """The columns a relative skill learns from, read from the recording's Parquet files
    (checked: each column there, of its size): ``skill`` (N, 13), ``width`` (N,),
    ``action`` (N, 7), ``ground`` (N, 4), ``episode`` and ``frame`` (N,); and the rate."""
    import pyarrow.parquet as pq  # the lerobot extra's

    root = Path(root)
    info_path = root / "meta" / "info.json"
    try:
        info = json.loads(info_path.read_text())
        fps = float(info["fps"])
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"{info_path}: no recording's info (its fps); record it with "
                         "python -m cake_drake.record") from None  # fmt: skip
    files = sorted((root / "data").glob("*/*.parquet"))
    if not files:
        raise InputError(f"{root}: no data/*/*.parquet; not a recording")
    wanted = {"observation.state": 8, "skill": SKILL_SIZE, "action": 7, "ground_action": 4}
    parts: dict[str, list[np.ndarray]] = {k: [] for k in (*wanted, "episode_index", "frame_index")}
    for path in files:
        try:
            table = pq.read_table(path)
        except (OSError, ValueError) as e:  # pyarrow's ArrowInvalid is a ValueError
            said = str(e)[:80]
            raise InputError(f"{path}: not a readable Parquet table ({said}); record it "
                             "again with python -m cake_drake.record") from None  # fmt: skip
        for key in parts:
            if key not in table.column_names:
                what = ("a recording of the hand's moves with the action under way "
                        "(record the skills_relative task)")  # fmt: skip
                raise InputError(f"{path}: no column {key!r}; a relative skill learns from {what}")
            column = table.column(key).combine_chunks()
            if key in wanted:
                values = column.flatten().to_numpy(zero_copy_only=False)
                if len(values) != len(column) * wanted[key]:
                    raise InputError(f"{path}: {key} is not {wanted[key]} numbers a frame")
                parts[key].append(values.reshape(len(column), wanted[key]))
            else:
                parts[key].append(column.to_numpy(zero_copy_only=False))
    cols = {k: np.concatenate(v) for k, v in parts.items()}
    return {
        "skill": cols["skill"].astype(np.float64),
        "width": cols["observation.state"][:, 7].astype(np.float64),
        "action": cols["action"].astype(np.float64),
        "ground": cols["ground_action"].astype(np.int64),
        "episode": cols["episode_index"].astype(np.int64),
        "frame": cols["frame_index"].astype(np.int64),
        "fps": np.float64(fps),
    }


def examples(
    frames: dict, n_obs: int, lookahead: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs (N, n_obs * 14: each frame's ``observation.relative`` after the ones before
    it in its segment, the segment's first repeated before it), moves (N, 4) and the
    gripper's label (N,: 1 closed) of every frame under an action. A frame's move is where
    the demonstrator's hand was headed ``lookahead`` frames later (the last frame before
    the action ends or the gripper changes, where that is sooner), from the action's
    target."""
    ground, episode, frame = frames["ground"], frames["episode"], frames["frame"]
    new = np.ones(len(frame), bool)
    new[1:] = (episode[1:] != episode[:-1]) | np.any(ground[1:] != ground[:-1], axis=1)
    new[1:] |= frame[1:] != frame[:-1] + 1
    first = np.flatnonzero(new)
    lengths = np.diff(np.r_[first, len(frame)])
    start = np.repeat(first, lengths)
    relative = np.column_stack([frames["skill"], frames["width"]])
    under = ground[:, 0] >= 0
    rows = np.flatnonzero(under)
    history = [relative[np.maximum(rows - k, start[rows])] for k in range(n_obs - 1, -1, -1)]
    x = np.concatenate(history, axis=1)
    # Where the hand was headed, from the action's target (observation.skill's 8-11: above
    # the cube for a pick, where the cube rests for a place): the demonstrator's move from
    # the hand, less where the target is from the hand; taken ``lookahead`` frames on, so
    # that the answer is always ahead of the hand (a target where the hand already is
    # would hold it there) and, at the end of a motion, exactly where it ends.
    # The heading looks no further than the gripper's next change: the hand goes to the
    # cube and stays there until the fingers have closed, whatever comes after.
    onto = rs.target_from_hand(relative)  # the move onto the target
    headed = frames["action"][:, MOVE_COLUMNS] - onto
    grip = frames["action"][:, GRIPPER_COLUMN] < 0.5
    phase = new.copy()
    phase[1:] |= grip[1:] != grip[:-1]
    phase_first = np.flatnonzero(phase)
    phase_end = np.repeat(
        np.r_[phase_first[1:], len(frame)], np.diff(np.r_[phase_first, len(frame)])
    )
    # Nor past the moment the hand comes over its target: a hand still crossing is headed
    # for the point over its target, not already down the descent after it (the
    # demonstrator crosses, then goes down; a heading half a second on cuts the corner,
    # and open fingers come down beside a tower's top cube and pull the tower over).
    over = np.r_[np.flatnonzero(np.linalg.norm(onto[:, :2], axis=1) < OVER), len(frame)]
    comes_over = over[np.searchsorted(over, np.arange(len(frame)))]  # len(frame): never
    limit = np.where(comes_over > np.arange(len(frame)), comes_over, len(frame))
    moves = headed[np.minimum.reduce([rows + lookahead, phase_end[rows] - 1, limit[rows]])]
    # The gripper's label a little ahead too (within the action): the hand at the cube
    # decides to close before its fingers show it, so the decision is learned from where
    # the hand is, not read off the fingers' width.
    action_end = start + np.repeat(lengths, lengths)
    ahead = np.minimum(np.arange(len(frame)) + GRIP_LOOKAHEAD, action_end - 1)
    # Where the hand has arrived where its motion ends and the gripper changes next (the
    # demonstrator waits there for its clock), the change is the label: a learner that
    # has arrived decides at once, from where it is.
    last = phase_end - 1
    # The hand (a place: the held cube) from the target, against where the motion ends.
    arrived = np.linalg.norm(-onto[:, :3] - headed[last, :3], axis=1) < ARRIVED
    changes = (phase_end < action_end) & arrived
    ahead = np.where(changes, np.minimum(phase_end, action_end - 1), ahead)
    closed = grip[ahead[rows]].astype(np.float64)
    return x, moves, closed


def augment(x: np.ndarray, moves: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """A batch of examples (``x`` as :func:`examples` gives them, (B, n_obs * 14); their
    ``moves``, (B, 4)) varied where the demonstrator's answer does not change, so that
    what does not matter is seen to vary (a share ``AUGMENTED`` of the frames, each
    observation of a frame alike). Copies; the inputs are untouched.

    - **The grasp.** In a place whose fingers hold the cube, the hand is moved about the
      cube (``GRASP_JITTER``): the cube stays where it is in the world, so everything the
      frame reads from the hand (the cube, its rest, the transit height, their yaws)
      moves alike, and both answers stay: where the held cube goes, from its rest
      (:func:`cake_drake.learning.skills.relative.target_from_hand`), and whether
      to let go of it, which the demonstrator decided from the cube at its rest. The
      fingers' width on it is varied by up to ``GRIP_JITTER``. Every demonstrated grasp
      is centred to a millimetre, and the fingers close on every cube to a tenth of one:
      a cube held a centimetre low, or fingers a millimetre narrower, would otherwise be
      a scene no frame showed (the width, which tells a held cube from a let-go one, was
      read to a tenth of a millimetre, and a hand stopped over its place on a
      millimetre's difference). Moving the cube alone would move it from its rest, and
      teach a release wherever the cube is: a cube held low let go of above its place.
    - **The transit height in a final descent.** Once the hand is over its target (a
      cube to grasp, or the held cube over its place) and going down to it, how high the
      towers elsewhere are does not change where it goes: the transit height
      (``observation.skill``'s 12, and a pick's target, 10, which is up at it) is moved
      anywhere from ``TRANSIT_CLEAR`` above the hand to ``TRANSIT_RAISE`` higher, a pick's
      move less what its target rose. Demonstrations of tall towers alone otherwise
      teach a hand far below its transit height that it is still high above its place:
      it stops short over a low one."""
    x, moves = np.array(x, np.float64), np.array(moves, np.float64)
    size = rs.WIDTH + 1
    steps = x.shape[1] // size
    now = x[:, -size:]
    chosen = rng.random(len(x)) < AUGMENTED
    width = now[:, rs.WIDTH]
    picking = now[:, 0] + now[:, 1] > 0.5
    holding = ~picking & (width < rs.LET_GO)
    reaching = picking & (width > rs.LET_GO)  # a pick's fingers open
    # The grasp: any frame of a place whose fingers hold the cube.
    rows = np.flatnonzero(chosen & holding)
    shift = rng.uniform(-1.0, 1.0, (len(rows), 4)) * GRASP_JITTER
    grip = rng.uniform(-GRIP_JITTER, GRIP_JITTER, len(rows))
    # The final descent: over the target, below the transit height, before the gripper's
    # change (a pick's fingers open, a place's closed on its cube).
    over = np.linalg.norm(rs.target_from_hand(now)[:, :2], axis=1) < OVER
    descending = chosen & over & (now[:, 12] > TRANSIT_CLEAR) & (holding | reaching)
    down = np.flatnonzero(descending)
    lowest = np.min(x[down][:, 12::size], axis=1)  # the hand's highest in the history
    rise = rng.uniform(TRANSIT_CLEAR - lowest, TRANSIT_RAISE)
    up = picking[down]
    for k in range(steps):
        x[rows, k * size + 4 : k * size + 8] += shift  # the cube, from the hand
        x[rows, k * size + 8 : k * size + 12] += shift  # its rest, and the rest's yaw
        x[rows, k * size + 12] += shift[:, 2]  # the transit height
        x[rows, k * size + rs.WIDTH] += grip
        x[down, k * size + 12] += rise
        x[down[up], k * size + 10] += rise[up]
    moves[down[up], 2] -= rise[up]
    return x, moves


def scaled(moves: np.ndarray) -> np.ndarray:
    """The moves (N, 4) as the network learns them: x y z on ``MOVE_SCALE``, yaw as is."""
    out = np.array(moves, np.float64)
    out[:, :3] = rs.compress(out[:, :3], MOVE_SCALE)
    return out


def losses(moves_std, logit, target_std, closed):
    """The training's two losses (torch tensors): the mean absolute error of the
    standardised moves, and the gripper head's binary cross-entropy on its logit against
    the label (1 closed, 0 open)."""
    import torch

    move = (moves_std - target_std).abs().mean()
    grip = torch.nn.functional.binary_cross_entropy_with_logits(logit, closed)
    return move, grip


def train_relative(
    root: Path,
    folder: Path,
    steps: int,
    batch_size: int,
    lr: float,
    hidden_dims: list[int],
    n_obs_steps: int,
    seed: int = 0,
    progress=print,
) -> dict:
    """Train the skill on the recording at ``root``; its ``skill.json`` and
    ``weights.npz`` written into ``folder`` (a staging folder: the caller puts it in
    place). The summary: frames, minutes, the gripper head's accuracy on the frames."""
    import torch
    from torch import nn

    t0 = time.perf_counter()
    frames = read_frames(root)
    x, moves, closed = examples(frames, n_obs_steps, LOOKAHEAD)
    if len(x) < batch_size:
        raise InputError(
            f"{root}: {len(x)} frames under an action; fewer than a batch ({batch_size})"
        )
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    # The scales are those of the varied examples (a centimetre off is no outlier).
    seen_x, seen_moves = augment(x, moves, rng)
    seen_moves = scaled(seen_moves)
    in_mean, in_std = seen_x.mean(0), np.maximum(seen_x.std(0), 1e-3)
    move_mean, move_std = seen_moves.mean(0), np.maximum(seen_moves.std(0), 1e-4)
    layers: list[nn.Module] = []
    width = x.shape[1]
    for hidden in hidden_dims:
        layers += [nn.Linear(width, hidden), nn.GELU(approximate="tanh")]
        width = hidden
    layers.append(nn.Linear(width, len(rs.MOVES) + 1))
    net = nn.Sequential(*layers)
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * min(s / steps, 1.0)))
    )
    cs = torch.as_tensor(closed, dtype=torch.float32)

    def standard(rows):
        bx, bm = augment(x[rows], moves[rows], rng)
        bm = scaled(bm)
        return (torch.as_tensor((bx - in_mean) / in_std, dtype=torch.float32),
                torch.as_tensor((bm - move_mean) / move_std, dtype=torch.float32))  # fmt: skip

    shown = max(steps // 10, 1)
    for step in range(1, steps + 1):
        idx = rng.integers(0, len(x), batch_size)
        bx, by = standard(idx)
        out_t = net(bx)
        move, grip = losses(out_t[:, :-1], out_t[:, -1], by, cs[idx])
        loss = move + grip
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % shown == 0 or step == steps:
            progress(f"step {step}/{steps}: move L1 {move.item():.4f} (std), "
                     f"gripper BCE {grip.item():.4f}")  # fmt: skip
    with torch.no_grad():
        out_all = net(torch.as_tensor((x - in_mean) / in_std, dtype=torch.float32))
        decided = (torch.sigmoid(out_all[:, -1]) >= 0.5).numpy()
    accuracy = float(np.mean(decided == (closed > 0.5)))
    minutes = (time.perf_counter() - t0) / 60
    trained = (f"trained {steps} steps on {len(x)} frames of {root.name} "
               f"({minutes:.1f} min, CPU)")  # fmt: skip
    meta = {
        "kind": rs.KIND, "format": rs.FORMAT, "input": rs.INPUT,
        "input_size": x.shape[1] // n_obs_steps, "n_obs_steps": n_obs_steps,
        "hidden_dims": list(hidden_dims), "moves": list(rs.MOVES),
        "gripper": {"head": "closed_logit", "threshold": rs.THRESHOLD},
        "move_scale_m": MOVE_SCALE,
        "lookahead_frames": LOOKAHEAD,
        "grip_lookahead_frames": GRIP_LOOKAHEAD,
        "augmented": {"share": AUGMENTED, "grasp_jitter": GRASP_JITTER.tolist(),
                      "grip_jitter_m": GRIP_JITTER,
                      "transit_raise_m": TRANSIT_RAISE},
        "trained": trained,
        "recipe": {"steps": steps, "batch_size": batch_size, "lr": lr, "seed": seed,
                   "recording": str(root), "frames": len(x)},
        "gripper_accuracy": round(accuracy, 4),
    }  # fmt: skip
    arrays = {"in_mean": in_mean, "in_std": in_std, "move_mean": move_mean, "move_std": move_std}
    linear = [m for m in net if isinstance(m, nn.Linear)]
    for k, m in enumerate(linear):
        arrays[f"w{k}"] = m.weight.detach().numpy().T.astype(np.float64)
        arrays[f"b{k}"] = m.bias.detach().numpy().astype(np.float64)
    folder = Path(folder)
    (folder / "skill.json").write_text(json.dumps(meta, indent=2) + "\n")
    np.savez_compressed(folder / "weights.npz", **arrays)
    return {"frames": len(x), "minutes": minutes, "gripper_accuracy": accuracy}


def train_recipe(root: Path, folder: Path, recipe, seed: int = 0, progress=print) -> dict:
    """:func:`train_relative` with a task's recipe (``training:``: steps, batch size,
    learning rate, layers, observations), as ``train`` and DAgger's rounds call it."""
    return train_relative(root, folder, recipe.steps, recipe.batch_size, recipe.lr or 1e-3,
                          list(recipe.hidden_dims), recipe.n_obs_steps, seed, progress)  # fmt: skip
