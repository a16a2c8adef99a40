"""Fitting the dynamic layer's residual to logged runs (``train --residual RUNS --out DIR``).

Each run is an output folder written with ``outputs.logs: true`` (its ``logs.npz``):
the features and labels of :mod:`cake_drake.dynamic.residual` are computed on every
sample, the last fifth of each run is held out, the weights are fitted by least squares
on the rest, and the folder ``DIR`` gets ``residual.json`` with the fit's figures: the
held-out samples' RMS label (what the model misses) while the hand holds a cube, before
and after the residual.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from cake_drake.dynamic.residual import FILE, Kinematics, ResidualModel, fit, samples
from cake_drake.errors import InputError
from cake_drake.formats import read_npz
from cake_drake.world.scene import make_control_plant

#: The share of each run's samples held out to measure the fit.
HELD_OUT = 0.2


#: What the residual reads of a run's ``logs.npz``: N samples of the arm's 7 joints.
LOG_SHAPES = {
    "t": ("N",),
    "q": ("N", 7),
    "v": ("N", 7),
    "a_d": ("N", 7),
    "tau_applied": ("N", 7),
    "fingers": ("N",),
}


def load_logs(run: Path) -> SimpleNamespace:
    """A run folder's ``logs.npz``, checked by :func:`cake_drake.formats.read_npz` (only what
    the residual reads, the rest refused by its headers if too large): seven joints, at
    least 10 samples, times that advance, finite numbers; one line otherwise."""
    path = Path(run) / "logs.npz" if Path(run).is_dir() else Path(run)
    if not path.is_file():
        raise InputError(f"{run}: no logs.npz; run the scenario with outputs.logs: true")
    expected = "a run's logs.npz (outputs.logs: true) of the 7-joint arm"
    logs = SimpleNamespace(**read_npz(path, expected, LOG_SHAPES))
    if len(logs.t) < 10:
        raise InputError(f"{path}: {len(logs.t)} samples; a run of at least 10 is needed")
    if not np.all(np.diff(logs.t) > 0):
        raise InputError(f"{path}: times in 't' must strictly increase (the accelerations "
                         "the residual is fitted to are differences over time)")  # fmt: skip
    bad = [k for k in LOG_SHAPES if not np.all(np.isfinite(getattr(logs, k)))]
    if bad:
        raise InputError(f"{path}: array {bad[0]!r} holds NaN or infinite values")
    return logs


def train_residual(runs: list[Path], out: Path, bound_nm: list[float] | None = None) -> dict:
    """Fit a residual to ``runs`` and write it to ``out``; the fit's figures."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise InputError(f"{out}: not empty; choose another --out")
    logs = [load_logs(r) for r in runs]  # every run refused before any work
    kin = Kinematics(make_control_plant())
    fit_phi, fit_y, test_phi, test_y = [], [], [], []
    for log in logs:
        phi, label = samples(log, kin)
        cut = int(len(label) * (1 - HELD_OUT))
        fit_phi.append(phi[:cut])
        fit_y.append(label[:cut])
        test_phi.append(phi[cut:])
        test_y.append(label[cut:])
    phi, label = np.concatenate(fit_phi), np.concatenate(fit_y)
    weights = fit(phi, label)
    if not np.all(np.isfinite(weights)):  # never written: a residual must be numbers
        raise InputError(f"{', '.join(str(r) for r in runs)}: the fit gave no finite weights "
                         "(samples that do not tell the joints' torques apart)")  # fmt: skip
    model = ResidualModel(weights=weights.tolist())
    if bound_nm is not None:
        model.bound_nm = list(bound_nm)
    held_phi, held_y = np.concatenate(test_phi), np.concatenate(test_y)
    # Where the hand holds a cube: what the residual is for (the hold features are on).
    held = np.any(held_phi[:, :, 0] != 0, axis=1)
    held_phi, held_y = (held_phi[held], held_y[held]) if held.any() else (held_phi, held_y)
    before = np.sqrt(np.mean(held_y**2, axis=0))
    after = np.sqrt(np.mean((held_y - model.torque(held_phi)) ** 2, axis=0))
    model.fit = {
        "runs": [Path(r).name for r in runs],
        "samples": int(len(label)),
        "held_out_samples": int(len(held_y)),
        "held_out_rms_nm_before": np.round(before, 4).tolist(),
        "held_out_rms_nm_after": np.round(after, 4).tolist(),
    }
    staging = out.with_name(f".{out.name}.staging-{os.getpid()}")
    model.save(staging)
    if out.exists():
        out.rmdir()
    staging.rename(out)
    return model.fit


def describe(out: Path) -> str:
    """One line: what the residual in ``out`` removes of the held-out error."""
    data = json.loads((Path(out) / FILE).read_text())["fit"]
    before, after = (
        np.asarray(data["held_out_rms_nm_before"]),
        np.asarray(data["held_out_rms_nm_after"]),
    )
    shown = lambda v: "/".join(f"{x:.2f}" for x in v)  # noqa: E731
    return (
        f"{out}: residual fitted on {len(data['runs'])} run{'s' * (len(data['runs']) != 1)} "
        f"({data['samples']} samples); "
        f"the model's error on the held-out samples while holding, joints 1-7 (N m RMS): "
        f"{shown(before)} without it, {shown(after)} with it"
    )
