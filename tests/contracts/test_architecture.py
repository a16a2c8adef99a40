"""The layers' order is a contract checked by import-linter (pyproject.toml's
``[tool.importlinter]``; ``make lint`` runs it too): it holds for the package as it is,
and it is broken by one import upward - shown on a copy of the package with one added.
Each package's docstring is a true map of its modules."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT


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


PACKAGES = sorted(p.parent for p in (ROOT / "cake_drake").rglob("__init__.py")
                  if "__pycache__" not in p.parts)  # fmt: skip


def _members(package: Path) -> list[str]:
    modules = [p.stem for p in package.glob("*.py") if p.stem not in ("__init__", "__main__")]
    packages = [p.name for p in package.iterdir() if (p / "__init__.py").is_file()]
    return sorted(modules + packages)


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_each_package_s_map_names_every_module_and_only_modules_it_has(package):
    """A package's docstring is its map: each of its modules named (``name``, ``name.py``
    or :mod:`.name`), and each module it names with a file or a relative :mod: there."""
    import ast

    doc = ast.get_docstring(ast.parse((package / "__init__.py").read_text())) or ""
    missing = [m for m in _members(package) if not re.search(rf"(?<!\w){m}(?!\w)", doc)]
    assert not missing, f"{package.relative_to(ROOT)}/__init__.py does not name {missing}"
    named = set(re.findall(r"``(\w+)\.py``", doc)) | set(re.findall(r":mod:`\.(\w+)`", doc))
    absent = sorted(named - set(_members(package)))
    assert not absent, f"{package.relative_to(ROOT)}/__init__.py names no such module {absent}"
