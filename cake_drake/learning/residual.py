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

#: The share of each run's samples held out to measure the fit.
HELD_OUT = 0.2


def load_logs(run: Path) -> SimpleNamespace:
    """A run folder's ``logs.npz``, with what the residual needs; one line otherwise."""
    path = Path(run) / "logs.npz" if Path(run).is_dir() else Path(run)
    if not path.is_file():
        raise InputError(f"{run}: no logs.npz; run the scenario with outputs.logs: true")
    try:
        with np.load(path) as data:
            logs = SimpleNamespace(**{k: data[k] for k in data.files})
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: unreadable ({e})") from None
    need = ("t", "q", "v", "a_d", "tau_applied", "fingers")
    missing = [k for k in need if not hasattr(logs, k)]
    if missing:
        raise InputError(f"{path}: lacks {', '.join(missing)}; run it again with this version")
    if len(logs.t) < 10:
        raise InputError(f"{path}: {len(logs.t)} samples; a run of at least 10 is needed")
    return logs


def train_residual(runs: list[Path], out: Path, bound_nm: list[float] | None = None) -> dict:
    """Fit a residual to ``runs`` and write it to ``out``; the fit's figures."""
    from cake_drake.world.scene import make_control_plant

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
