"""The layers' order is a contract checked by import-linter (pyproject.toml's
``[tool.importlinter]``; ``make lint`` runs it too): it holds for the package as it is,
and it is broken by one import upward - shown on a copy of the package with one added."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _lint(cwd: Path, pythonpath: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(pythonpath)}
    code = "import sys; from importlinter.cli import lint_imports_command as lint; sys.exit(lint())"
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)  # fmt: skip


def test_the_layers_contract_holds():
    r = _lint(ROOT, ROOT)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "1 kept, 0 broken" in r.stdout, r.stdout[-2000:]


def test_an_import_upward_breaks_the_contract(tmp_path):
    # A copy of the package in which the symbolic layer reaches up into the pipeline.
    shutil.copytree(ROOT / "cake_drake", tmp_path / "cake_drake",
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    plans = tmp_path / "cake_drake" / "symbolic" / "plans.py"
    plans.write_text(plans.read_text() + "\n\ndef _upward():\n    import cake_drake.pipeline\n")
    r = _lint(tmp_path, tmp_path)
    assert r.returncode != 0, r.stdout[-2000:]
    assert "0 kept, 1 broken" in r.stdout
    assert "cake_drake.symbolic is not allowed to import cake_drake.pipeline" in r.stdout
    assert "cake_drake.symbolic.plans -> cake_drake.pipeline" in r.stdout
