"""Training the learned eyes (:mod:`cake_drake.perception.learned`) on a frames dataset.

The point network is trained with PyTorch on the CPU: every sighting drawn rotated about
the vertical by a random angle (points, rays and labels alike: the cameras stay where
they are, but a cube may face any way), each point's vote held to the true centre and
the true ``cos 4 psi, sin 4 psi``, and so is their weighted mean, which is what a run
reads. The
last tenth of the runs is held out, and the weights kept are those whose held-out
position error's 95th percentile is lowest at a check.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.learning.data.frames import read_frames
from cake_drake.perception.fit import HALF
from cake_drake.perception.learned import ANSWER, FEATURES, FORMAT, KIND, weight_shapes

FILES = ("perception.json", "weights.npz", "progress.csv")


def _model(width: int):
    import torch

    half = width // 2

    class PointVotes(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.l1 = torch.nn.Linear(FEATURES, half)
            self.l2 = torch.nn.Linear(half, width)
            self.l3 = torch.nn.Linear(half + width, width)
            self.l4 = torch.nn.Linear(width, half)
            self.l5 = torch.nn.Linear(half, ANSWER)

        def forward(self, x):
            relu = torch.relu
            h1 = relu(self.l1(x))
            h2 = relu(self.l2(h1))
            g = h2.max(dim=1, keepdim=True).values.expand_as(h2)
            h3 = relu(self.l3(torch.cat([h1, g], dim=-1)))
            return self.l5(relu(self.l4(h3)))

    return PointVotes()


def export(model) -> dict[str, np.ndarray]:
    """The model's weights as :func:`weight_shapes` names them (NumPy's ``x @ w``)."""
    out = {}
    for k in range(1, 6):
        layer = getattr(model, f"l{k}")
        out[f"w{k}"] = layer.weight.detach().numpy().T.astype(np.float32).copy()
        out[f"b{k}"] = layer.bias.detach().numpy().astype(np.float32).copy()
    return out


def _labels(arrays: dict) -> tuple[np.ndarray, np.ndarray]:
    centre = (arrays["position"] - arrays["median"]) / HALF
    yaw = arrays["yaw"].astype(np.float64)
    return centre.astype(np.float32), np.stack([np.cos(4 * yaw), np.sin(4 * yaw)], 1).astype(
        np.float32
    )


def _rotate(x, centre, cs, angle):
    """Rotate a batch about the vertical by ``angle`` (B,): points, rays, the centre and
    the yaw's ``cos 4 psi, sin 4 psi``."""
    import torch

    c, s = torch.cos(angle), torch.sin(angle)
    R = torch.stack([torch.stack([c, -s], -1), torch.stack([s, c], -1)], -2)  # (B, 2, 2)
    x = x.clone()
    x[..., 0:2] = torch.einsum("bij,bnj->bni", R, x[..., 0:2])
    x[..., 3:5] = torch.einsum("bij,bnj->bni", R, x[..., 3:5])
    centre = centre.clone()
    centre[:, 0:2] = torch.einsum("bij,bj->bi", R, centre[:, 0:2])
    c4, s4 = torch.cos(4 * angle), torch.sin(4 * angle)
    cs = torch.stack([cs[:, 0] * c4 - cs[:, 1] * s4, cs[:, 1] * c4 + cs[:, 0] * s4], -1)
    return x, centre, cs


def weighed(x, votes):
    """A batch's answers: the weighted centre (B, 3) and ``cos 4 psi, sin 4 psi`` (B, 2)."""
    import torch

    w = torch.softmax(votes[..., 5], dim=1)[..., None]
    return (w * (x[..., :3] + votes[..., :3])).sum(1), (w * votes[..., 3:5]).sum(1)


def errors_of(model, x, centre, cs, batch: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Every sighting's position error (mm) and yaw error (degrees, modulo 90)."""
    import torch

    pos, yaw = [], []
    with torch.no_grad():
        for k in range(0, len(x), batch):
            xb = x[k : k + batch]
            est, m = weighed(xb, model(xb))
            pos.append(((est - centre[k : k + batch]).norm(dim=1) * HALF * 1000).numpy())
            a = torch.atan2(m[:, 1], m[:, 0]) / 4
            b = torch.atan2(cs[k : k + batch, 1], cs[k : k + batch, 0]) / 4
            d = torch.remainder(a - b + math.pi / 4, math.pi / 2) - math.pi / 4
            yaw.append(np.degrees(d.abs().numpy()))
    return np.concatenate(pos), np.concatenate(yaw)


def read_all(frames: list[Path]) -> tuple[dict, dict[str, np.ndarray]]:
    """Several frames datasets as one: their runs numbered on, their cameras the same."""
    metas, parts = zip(*(read_frames(f) for f in frames), strict=True)
    for f, m in zip(frames[1:], metas[1:], strict=True):
        if m["cameras"] != metas[0]["cameras"]:
            raise InputError(f"{f}: recorded with other cameras than {frames[0]}")
    offsets = np.cumsum([0] + [len(m["runs"]) for m in metas[:-1]])
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    arrays["run"] = np.concatenate([p["run"] + o for p, o in zip(parts, offsets, strict=True)])
    seeds = [m["seeds"] for m in metas]
    return {
        "cameras": metas[0]["cameras"],
        "seeds": seeds,
        "runs": sum(len(m["runs"]) for m in metas),
    }, arrays


def train_perception(
    frames: list[Path],
    out,
    steps: int,
    batch_size: int,
    lr: float,
    width: int,
    seed: int,
    minutes: float | None = None,
    checks: int = 20,
    progress=print,
) -> dict:
    """Train on the datasets ``frames`` into the staged folder ``out`` (an
    :class:`~cake_drake.outputs.files.OutputDir`); the training's figures."""
    import torch

    t0 = time.perf_counter()
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    meta, arrays = read_all(frames)
    runs = arrays["run"]
    n_runs = int(runs.max()) + 1
    held = runs >= n_runs - max(1, n_runs // 10) if n_runs > 1 else np.zeros(len(runs), bool)
    if held.all() or not held.any():  # a single run: its last tenth of sightings
        held = np.arange(len(runs)) >= int(0.9 * len(runs))
    x = torch.from_numpy(arrays["features"].astype(np.float32))
    centre, cs = (torch.from_numpy(a) for a in _labels(arrays))
    train_idx, test_idx = np.flatnonzero(~held), np.flatnonzero(held)
    model = _model(width)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    every = max(1, steps // checks)
    best, kept, rows = None, export(model), []
    step = 0
    for step in range(1, steps + 1):
        for group in opt.param_groups:  # cosine to a hundredth
            group["lr"] = lr * (0.01 + 0.99 * 0.5 * (1 + math.cos(math.pi * step / steps)))
        pick = torch.from_numpy(rng.choice(train_idx, batch_size))
        xb, cb, sb = _rotate(x[pick], centre[pick], cs[pick], torch.rand(batch_size) * 2 * math.pi)
        votes = model(xb)
        point = xb[..., :3] + votes[..., :3]
        est, cs_est = weighed(xb, votes)
        loss = (
            torch.nn.functional.smooth_l1_loss(point, cb[:, None].expand_as(point), beta=0.05)
            + torch.nn.functional.smooth_l1_loss(est, cb, beta=0.02)
            + 0.1 * ((votes[..., 3:5] - sb[:, None]) ** 2).mean()
            + 0.5 * ((cs_est - sb) ** 2).mean()
        )
        opt.zero_grad()
        loss.backward()
        opt.step()
        late = minutes is not None and time.perf_counter() - t0 > 60 * minutes
        if step % every == 0 or step == steps or late:
            pos, yaw = errors_of(model, x[test_idx], centre[test_idx], cs[test_idx])
            row = {"step": step, "minutes": round((time.perf_counter() - t0) / 60, 2),
                   "loss": round(loss.item(), 5), "median_mm": round(float(np.median(pos)), 3),
                   "p95_mm": round(float(np.percentile(pos, 95)), 3),
                   "yaw_p95_deg": round(float(np.percentile(yaw, 95)), 3)}  # fmt: skip
            rows.append(row)
            if best is None or row["p95_mm"] < best["p95_mm"]:
                best, kept = row, export(model)
            progress(
                f"step {step}: held-out {row['median_mm']:.2f} / {row['p95_mm']:.2f} mm, "
                f"yaw p95 {row['yaw_p95_deg']:.2f} deg ({row['minutes']:.1f} min)"
            )
        if late:
            break
    np.savez(out.path("weights.npz"), **kept)
    assert set(kept) == set(weight_shapes(width))
    with open(out.path("progress.csv"), "w", encoding="utf-8") as f:
        f.write(",".join(rows[0]) + "\n")
        for row in rows:
            f.write(",".join(str(v) for v in row.values()) + "\n")
    info = {
        "samples": int(len(train_idx)), "held_out": int(len(test_idx)), "steps": step,
        "batch_size": batch_size, "lr": lr, "seed": seed,
        "minutes": round((time.perf_counter() - t0) / 60, 2), "kept": best,
        "frames": [str(f) for f in frames], "frames_seeds": meta["seeds"],
    }  # fmt: skip
    config = {"kind": KIND, "format": FORMAT, "width": width, "cameras": meta["cameras"],
              "training": info}  # fmt: skip
    out.write_text("perception.json", json.dumps(config, indent=1) + "\n")
    return info
