"""A policy's success rate, measured: episodes over seeded problems, with intervals.

``evaluate``: a policy over seeded problems; success with a 95 % Wilson interval, per
problem size, steps, time and the reasons episodes ended. A learned skill checkpoint is
evaluated under the planner: each episode is the same problem and placement run with the
plan, the execution monitor and the skills as the geometric layer
(:func:`cake_drake.learning.skills.checkpoints.episode`), and the summary says how often the
monitor's repeats and replans rescued an episode.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict

import numpy as np

from cake_drake.learning.parallel import map_ordered
from cake_drake.learning.rollout import FRAMES, EpisodeSpec, rollout
from cake_drake.learning.skills.checkpoints import episode as skill_episode
from cake_drake.scenario import SKILL_POLICY


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a success rate: always within [0, 1] and
    holding the rate itself (rounding alone would put the upper bound of 6/6 at
    0.9999999999999999, below the rate)."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, min(p, centre - half)), min(1.0, max(p, centre + half))


def _evaluate_one(args) -> dict:
    """One episode's row, no frames but, with ``final``, a failed episode's last picture
    (run in a worker)."""
    spec, seed, final = args
    if spec.policy == SKILL_POLICY:  # learned skills under the planner: a run per episode
        return skill_episode(spec, seed)
    ep = rollout(spec, seed, record=False, final_frame=final)
    row = {k: v for k, v in asdict(ep).items() if k not in FRAMES}
    return {**row, "final": ep.final} if ep.final is not None else row


def evaluate(
    spec: EpisodeSpec, seeds: list[int], workers: int, ray=None, frames: int = 0
) -> tuple[list[dict], dict]:
    """Rows (one per episode, in seed order) and the summary of ``spec.policy`` over
    ``seeds``, on a local pool or on ``ray``; the first ``frames`` failed episodes' rows
    keep their last picture (``final``)."""
    jobs = [(spec, s, bool(frames)) for s in seeds]
    rows = map_ordered(_evaluate_one, jobs, workers, ray)
    for row in [r for r in rows if "final" in r][frames:]:
        del row["final"]
    wins = sum(r["success"] for r in rows)
    lo, hi = wilson(wins, len(rows))
    sizes = {}
    for n in sorted({r["blocks"] for r in rows}):
        sub = [r for r in rows if r["blocks"] == n]
        k = sum(r["success"] for r in sub)
        sizes[str(n)] = {"episodes": len(sub), "success": k, "ci95": list(wilson(k, len(sub)))}
    summary = {
        "policy": spec.label,
        "control_mode": spec.control_mode,
        "episodes": len(rows),
        "success": wins,
        "rate": wins / len(rows) if rows else 0.0,
        "ci95": [lo, hi],
        "per_size": sizes,
        "mean_steps": float(np.mean([r["steps"] for r in rows])) if rows else 0.0,
        "mean_wall_s": float(np.mean([r["wall_s"] for r in rows])) if rows else 0.0,
        "reasons": dict(Counter(r["reason"] for r in rows)),
        # Where the failures stopped: how often each goal fact was missing at their end.
        "missing_at_end": dict(
            Counter(f for r in rows if not r["success"] for f in r.get("missing", ())).most_common()
        ),
    }
    if rows and "repeats" in rows[0]:  # under the planner: what the monitor's loop did
        mended = [r for r in rows if r["repeats"] or r["replans"]]
        summary["monitor"] = {
            "episodes_with_repeats_or_replans": len(mended),
            "rescued": sum(r["success"] for r in mended),
            "repeats": int(sum(r["repeats"] for r in rows)),
            "replans": int(sum(r["replans"] for r in rows)),
        }
        places = [p for r in rows for p in r.get("places_mm", ())]
        summary["places"] = {
            "count": len(places),
            "median_mm": float(np.median(places)) if places else None,
            "p95_mm": float(np.percentile(places, 95)) if places else None,
        }
        summary["mean_sim_s"] = float(np.mean([r["sim_s"] for r in rows]))
    return rows, summary
