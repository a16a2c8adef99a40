"""The library never imports the command line: only entry points (``__main__``) do."""

from __future__ import annotations

import ast
from pathlib import Path

import cake_drake

PACKAGE = Path(cake_drake.__file__).parent
#: Thin ``python -m cake_drake.X`` entry points: they exist to call the CLI.
ENTRY_POINTS = {"cli.py", "plan.py", "run.py", "sweep.py", "validate.py", "saycan.py"}


def imports_cli(path: Path) -> bool:
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module == "cake_drake.cli":
            return True
        if isinstance(node, ast.ImportFrom) and node.module == "cake_drake":
            if any(a.name == "cli" for a in node.names):
                return True
        if isinstance(node, ast.Import) and any(a.name == "cake_drake.cli" for a in node.names):
            return True
    return False


def test_no_library_module_imports_the_cli():
    offenders = [
        str(p.relative_to(PACKAGE))
        for p in sorted(PACKAGE.rglob("*.py"))
        if p.name != "__main__.py"
        and not (p.parent == PACKAGE and p.name in ENTRY_POINTS)
        and imports_cli(p)
    ]
    assert offenders == []
