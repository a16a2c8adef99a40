"""The first contact: system-packages.txt and the Makefile that installs it.

Every external program the project runs (``subprocess``, ``shutil.which``, ``os.system``,
notebook ``!`` lines) must come from a package listed in system-packages.txt or be the
venv's own Python, so that `make run` / `make test` on a bare machine bring it in. The
Makefile's package step is run here against stand-ins for dpkg-query, id, sudo and apt-get.
"""

from __future__ import annotations

import ast
import json
import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.helpers import ROOT

PACKAGES_FILE = ROOT / "system-packages.txt"
SOURCES = ("cake_drake", "tests", "benchmarks", "examples", "models")
VENV = "the venv's Python"

RUNNERS = {
    ("subprocess", name) for name in ("run", "Popen", "call", "check_call", "check_output")
} | {("os", "system"), ("shutil", "which"), ("asyncio", "create_subprocess_exec")}
RUNNERS |= {("os", name) for name in ("execv", "execvp", "execl", "execlp", "spawnv", "spawnvp")}
# The project's door for a program in a process group it owns runs only what its caller
# hands it (Fast Downward's driver, under the venv's Python; tests/test_processes.py's
# small children from Debian's Essential packages): not a program of its own.
HANDED = Path("cake_drake") / "processes.py"


@dataclass(frozen=True)
class Entry:
    package: str
    goal: str
    programs: tuple[str, ...]


def read_packages(path: Path = PACKAGES_FILE) -> list[Entry]:
    entries = []
    for line in path.read_text().splitlines():
        fields = line.split("#", 1)[0].split()
        if fields:
            entries.append(Entry(fields[0], fields[1], tuple(fields[2:])))
    return entries


# --- which programs does the code run? --------------------------------------------------


def _runner(call: ast.Call, aliases: dict[str, tuple[str, str]]) -> bool:
    f = call.func
    if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
        return (f.value.id, f.attr) in RUNNERS
    return isinstance(f, ast.Name) and aliases.get(f.id) in RUNNERS


class _Programs(ast.NodeVisitor):
    """Collects (line, program or None when it cannot be told) for every runner call."""

    def __init__(self, tree: ast.Module):
        self.found: list[tuple[int, str | None]] = []
        self.aliases = {
            alias.asname or alias.name: (node.module, alias.name)
            for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) and node.module
            for alias in node.names
        }
        self.scopes: list[ast.AST] = [tree]

    def visit_FunctionDef(self, node):
        self.scopes.append(node)
        self.generic_visit(node)
        self.scopes.pop()

    visit_AsyncFunctionDef = visit_FunctionDef

    def visit_Call(self, node: ast.Call):
        if _runner(node, self.aliases) and node.args:
            for program in self.program(node.args[0], depth=0):
                self.found.append((node.lineno, program))
        self.generic_visit(node)

    def program(self, e: ast.AST, depth: int) -> list[str | None]:
        """What ``e`` (a runner's first argument) names as the program to run."""
        if depth > 5:
            return [None]
        if any(
            isinstance(n, ast.Attribute) and n.attr == "executable" and getattr(n.value, "id", "")
            == "sys" for n in ast.walk(e)
        ):  # fmt: skip
            return [VENV]
        if isinstance(e, ast.Constant) and isinstance(e.value, str):
            return [shlex.split(e.value)[0] if e.value.strip() else None]
        if isinstance(e, (ast.List, ast.Tuple)) and e.elts:
            return self.program(e.elts[0], depth + 1)
        if isinstance(e, ast.Starred):
            return self.program(e.value, depth + 1)
        if isinstance(e, ast.BinOp):
            return self.program(e.left, depth + 1)
        if isinstance(e, ast.Call):
            if _runner(e, self.aliases):
                return []  # a shutil.which(...) result: that call is checked itself
            if isinstance(e.func, ast.Name) and e.func.id in ("str", "Path") and e.args:
                return self.program(e.args[0], depth + 1)
        if isinstance(e, ast.Name):
            if e.id == "OLDEST":  # .venv-oldest's Python (made by make test)
                return [VENV]
            values = self.values_of(e.id)
            return [p for v in values for p in self.program(v, depth + 1)] if values else [None]
        return [None]

    def values_of(self, name: str) -> list[ast.AST]:
        """What ``name`` is bound to in the enclosing function and the module."""
        found: list[ast.AST] = []
        for scope in reversed(self.scopes):
            if isinstance(scope, (ast.FunctionDef, ast.AsyncFunctionDef)):
                args = scope.args
                positional = args.posonlyargs + args.args
                defaults = dict(
                    zip([a.arg for a in positional[::-1]], args.defaults[::-1], strict=False)
                )
                defaults |= {
                    a.arg: d
                    for a, d in zip(args.kwonlyargs, args.kw_defaults, strict=True)
                    if d is not None
                }
                if name in defaults:
                    found.append(defaults[name])
            for node in ast.walk(scope):
                if isinstance(node, ast.Assign) and any(
                    isinstance(t, ast.Name) and t.id == name for t in node.targets
                ):
                    found.append(node.value)
                elif isinstance(node, ast.AnnAssign) and getattr(node.target, "id", "") == name:
                    if node.value is not None:
                        found.append(node.value)
            if found:
                return found
        return found


def programs_in_python(source: str) -> list[tuple[int, str | None]]:
    tree = ast.parse(source)
    visitor = _Programs(tree)
    visitor.visit(tree)
    return visitor.found


def programs_run() -> dict[str, list[str]]:
    """Program -> where it is run (``path:line``); ``None`` for a program not told."""
    where: dict[str, list[str]] = {}
    files = [p for d in SOURCES for p in sorted((ROOT / d).rglob("*.py"))
             if p.relative_to(ROOT) != HANDED]  # fmt: skip
    for path in files:
        for line, program in programs_in_python(path.read_text()):
            where.setdefault(program, []).append(f"{path.relative_to(ROOT)}:{line}")
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for k, cell in enumerate(json.loads(nb.read_text())["cells"]):
            if cell["cell_type"] != "code":
                continue
            code = "".join(cell["source"])
            shell = [ln.strip()[1:] for ln in code.splitlines() if ln.strip().startswith("!")]
            python = "\n".join("" if ln.strip().startswith(("!", "%")) else ln
                               for ln in code.splitlines())  # fmt: skip
            found = [(0, shlex.split(s)[0]) for s in shell if s.strip()]
            found += programs_in_python(python)
            for _, program in found:
                where.setdefault(program, []).append(f"{nb.relative_to(ROOT)} cell {k}")
    return where


def test_every_program_the_code_runs_comes_from_a_listed_package():
    listed = {program for entry in read_packages() for program in entry.programs}
    where = programs_run()
    unknown = {p: w for p, w in where.items() if p is not None and p != VENV and p not in listed}
    assert not unknown, (
        f"programs run but not provided by a package in {PACKAGES_FILE.name}: {unknown}"
    )
    untold = where.get(None, [])
    assert not untold, f"cannot tell which program these run (name it in a constant): {untold}"


def test_the_scan_finds_the_programs_we_know_of():
    where = programs_run()
    assert "dot" in where and "chromium" in where and VENV in where


def test_the_scan_reads_through_names_defaults_and_which():
    source = (
        "import shutil, subprocess, sys\n"
        "TOOL = 'convert'\n"
        "def f(dot='dot'):\n"
        "    exe = shutil.which(dot)\n"
        "    subprocess.run([exe, '-Tsvg'])\n"
        "    subprocess.run([TOOL, 'x'])\n"
        "    cmd = [sys.executable, '-m', 'x']\n"
        "    subprocess.run(cmd + ['y'])\n"
        "    subprocess.run('ffmpeg -i a', shell=True)\n"
        "    subprocess.run(make_command())\n"
    )
    assert [p for _, p in programs_in_python(source)] == [
        "dot",
        "convert",
        VENV,
        "ffmpeg",
        None,
    ]


def test_the_package_list_is_well_formed():
    entries = read_packages()
    assert entries and all(e.goal in ("run", "test") for e in entries)
    names = [e.package for e in entries]
    assert len(names) == len(set(names)), "a package is listed twice"
    assert {"graphviz", "chromium", "libegl1"} <= set(names)


# --- the Makefile's package step, against stand-ins ---------------------------------------


def _stub(folder: Path, name: str, body: str) -> None:
    path = folder / name
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


def _make(goal: str, folder: Path, uid: int, installed: bool, sudo_ok: bool):
    log = folder / "calls.log"
    _stub(folder, "dpkg-query", "echo 'install ok installed'" if installed else "exit 1")
    _stub(folder, "id", f"echo {uid}")
    _stub(folder, "sudo", f'echo "sudo $*" >> {log}; ' + ('[ "$1" = -n ] && exit 0; "$@"'
                                                         if sudo_ok else "exit 1"))  # fmt: skip
    _stub(folder, "apt-get", f'echo "apt-get $*" >> {log}')
    env = {**os.environ, "PATH": f"{folder}{os.pathsep}/usr/bin{os.pathsep}/bin"}
    r = subprocess.run(
        [shutil.which("make"), "-s", "-C", str(ROOT), goal],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    return r, (log.read_text() if log.exists() else "")


@pytest.fixture
def stubs(tmp_path):
    if shutil.which("make") is None:
        pytest.skip("make is not installed")
    return tmp_path


def test_missing_packages_without_root_stop_with_one_apt_get_line(stubs):
    r, calls = _make("system-packages-test", stubs, uid=1000, installed=False, sudo_ok=False)
    assert r.returncode != 0
    ours = [ln for ln in r.stderr.splitlines() if not ln.startswith("make")]
    assert len(ours) == 1, r.stderr
    wanted = " ".join(e.package for e in read_packages())
    assert ours[0].endswith(f"sudo apt-get install -y {wanted}"), ours[0]
    assert "apt-get" not in calls


def test_run_needs_only_the_run_packages(stubs):
    r, _ = _make("system-packages-run", stubs, uid=1000, installed=False, sudo_ok=False)
    line = r.stderr.splitlines()[0]
    assert "libegl1" in line and "graphviz" not in line and "chromium" not in line


def test_missing_packages_as_root_are_installed(stubs):
    r, calls = _make("system-packages-test", stubs, uid=0, installed=False, sudo_ok=False)
    assert r.returncode == 0, r.stderr
    install = [ln for ln in calls.splitlines() if " install " in ln]
    assert len(install) == 1
    assert all(e.package in install[0].split() for e in read_packages())
    assert "apt-get -o DPkg::Lock::Timeout=900 update" in calls and "sudo" not in calls


def test_missing_packages_with_passwordless_sudo_are_installed_through_it(stubs):
    r, calls = _make("system-packages-test", stubs, uid=1000, installed=False, sudo_ok=True)
    assert r.returncode == 0, r.stderr
    assert "sudo flock -w 900 /tmp/.cake_drake-apt.lock env DEBIAN_FRONTEND=noninteractive" in calls


def test_nothing_to_do_when_everything_is_installed(stubs):
    r, calls = _make("system-packages-test", stubs, uid=1000, installed=True, sudo_ok=False)
    assert r.returncode == 0 and r.stdout == "" and r.stderr == "" and calls == ""


# --- which Python packages each command installs ------------------------------------------
#
# `make run` installs the base dependencies only; `make test` adds the `test` extra on the
# same .venv. Read from the Makefile with `make -n` (nothing is installed): the pip
# commands each goal would run, from a fresh checkout and from each stamp's state.

PIP_INSTALL = re.compile(r"-m pip install --quiet -e (\S+)")
BASE, TEST = ".", "'.[test]'"


def _installs(folder: Path, goal: str, stamps: dict[str, int]) -> list[str]:
    """What ``make -n GOAL`` would ``pip install -e`` in a copy of the checkout's Makefile
    whose .venv holds ``stamps`` (name -> seconds after pyproject.toml's last change)."""
    work = folder / goal
    (work / "cake_drake").mkdir(parents=True)
    (work / "cake_drake" / "__init__.py").write_text("")
    for name in ("Makefile", "pyproject.toml", "system-packages.txt"):
        shutil.copy(ROOT / name, work / name)
    changed = 1_700_000_000
    os.utime(work / "pyproject.toml", (changed, changed))
    os.utime(work / "cake_drake" / "__init__.py", (changed - 10, changed - 10))
    if stamps:
        (work / ".venv" / "bin").mkdir(parents=True)
        (work / ".venv" / "bin" / "python").write_text("")
        for name, after in {**stamps, ".bytecode": max(stamps.values())}.items():
            (work / ".venv" / name).write_text("")
            os.utime(work / ".venv" / name, (changed + after, changed + after))
    r = subprocess.run(
        [shutil.which("make"), "-n", "-C", str(work), goal],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    return [m.group(1) for m in PIP_INSTALL.finditer(r.stdout)]


AFTER_RUN = {".installed-run": 5}
AFTER_TEST = {".installed-run": 5, ".installed-test": 6}


@pytest.mark.parametrize(
    "state, stamps, run, test",
    [
        ("a fresh checkout", {}, [BASE], [BASE, TEST]),
        ("after make run", AFTER_RUN, [], [TEST]),
        ("after make test", AFTER_TEST, [], []),
        ("pyproject.toml changed", {".installed-run": -5, ".installed-test": -4}, [BASE],
         [BASE, TEST]),
    ],
)  # fmt: skip
def test_make_run_installs_no_extra_and_make_test_adds_the_test_extra(
    stubs, state, stamps, run, test
):
    assert _installs(stubs, "run", stamps) == run, state
    assert _installs(stubs, "test", stamps) == test, state


def test_the_stamps_test_reads_are_the_makefiles():
    """The states above name the Makefile's own stamps (a renamed stamp fails here)."""
    text = (ROOT / "Makefile").read_text()
    for stamp in AFTER_TEST:
        assert f"$(VENV)/{stamp}" in text, stamp
    assert "pip install --quiet -e .\n" in text and "pip install --quiet -e '.[test]'" in text


def _base_closure() -> set[str]:
    """The distributions the base dependencies of pyproject.toml bring in (installed
    requirements, followed without extras), names normalised."""
    import tomllib
    from importlib.metadata import PackageNotFoundError, requires

    from packaging.requirements import Requirement

    def norm(name: str) -> str:
        return re.sub(r"[-_.]+", "-", name).lower()

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    todo = [Requirement(r) for r in project["dependencies"]]
    seen = {norm(project["name"])}
    while todo:
        req = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": ""}):
            continue
        if norm(req.name) in seen:
            continue
        seen.add(norm(req.name))
        try:
            todo += [Requirement(r) for r in requires(req.name) or []]
        except PackageNotFoundError:
            continue  # not installed here: nothing of it can be imported either
    return seen


@pytest.mark.slow
def test_the_main_job_imports_only_what_the_base_dependencies_install(tmp_path):
    """`make run` installs no extra, so `python -m cake_drake.run --mode torque` must not
    import one (here every extra is installed, and would be found silently)."""
    from importlib.metadata import packages_distributions

    script = (
        "import json, sys\n"
        "before = {m.split('.')[0] for m in sys.modules}\n"
        "from cake_drake.commands.run import main_run\n"
        "from cake_drake.errors import run_cli\n"
        "code = run_cli(main_run, ['--mode', 'torque', '--quiet', '--out', 'o'])\n"
        "now = {m.split('.')[0] for m in sys.modules}\n"
        "open('modules.json', 'w').write(json.dumps({'code': code, 'new': sorted(now - before)}))\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True,
        timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    found = json.loads((tmp_path / "modules.json").read_text())
    assert found["code"] == 0, r.stderr
    owners = packages_distributions()
    closure = _base_closure()
    outside = {
        module: owners[module]
        for module in found["new"]
        if module in owners
        and not any(re.sub(r"[-_.]+", "-", d).lower() in closure for d in owners[module])
    }
    assert not outside, f"imported from distributions outside the base dependencies: {outside}"
    assert {"pydrake", "numpy", "pyperplan", "yaml"} <= set(found["new"])


# --- which Python makes .venv --------------------------------------------------------------


def _pythons(folder: Path, minors: list[int]) -> dict:
    """An environment whose PATH holds only stand-ins for python3.MINOR (answering the
    Makefile's version check as that Python would) and the few tools make needs."""
    folder.mkdir()
    for minor in minors:
        _stub(folder, f"python3.{minor}", 'case "$2" in *"(3, 13)"*) n=13;; *"(3, 12)"*) n=12;; '
              f'*) n=11;; esac; [ {minor} -ge "$n" ]')  # fmt: skip
    (folder / "make").symlink_to(shutil.which("make"))
    return {**os.environ, "PATH": str(folder)}


def _venv_python(goal: str, env: dict):
    r = subprocess.run(
        [shutil.which("make"), "-n", "-C", str(ROOT), goal, "VENV=/nonexistent/.venv"],
        env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    lines = r.stdout.splitlines()
    made = [ln.split()[0] for ln in lines if ln.endswith("-m venv /nonexistent/.venv")]
    return r, made


@pytest.mark.parametrize(
    "minors, goal, chosen",
    [([12, 13], "test", "python3.13"), ([12], "test", "python3.12"),
     ([11, 12], "run", "python3.12"), ([11], "run", "python3.11")],
)  # fmt: skip
def test_the_newest_python_found_makes_the_venv(stubs, minors, goal, chosen):
    env = _pythons(stubs / "bin", minors)
    if minors == [11]:  # python3 is what a Debian 12 has
        (stubs / "bin" / "python3").symlink_to(stubs / "bin" / "python3.11")
        chosen = "python3"
    r, made = _venv_python(goal, env)
    assert r.returncode == 0, r.stderr
    assert made == [str(stubs / "bin" / chosen)], r.stdout


def test_make_test_without_python_3_12_is_one_line_before_anything_runs(stubs):
    env = _pythons(stubs / "bin", [11])
    r, made = _venv_python("test", env)
    assert r.returncode != 0 and not made
    assert "apt-get" not in r.stdout, "it stopped after the Debian packages"
    lines = [ln for ln in r.stderr.splitlines() if "needs Python" in ln]
    assert len(lines) == 1 and "make test needs Python 3.12 or newer" in lines[0], r.stderr
    assert "uv python install 3.12" in lines[0] and "pyenv" in lines[0]


# --- the oldest supported pair -------------------------------------------------------------

OLDEST = ROOT / ".venv-oldest" / "bin" / "python"  # the scan above counts it as a venv's Python


@pytest.mark.slow
def test_the_main_job_runs_on_the_oldest_supported_pair(tmp_path):
    """`make test` makes .venv-oldest (Python 3.11, Drake 1.51.1) where a Python 3.11 is
    found: the README's main job builds the tower there, and a learning command says in
    one line what it needs (exit 2) instead of failing inside LeRobot."""
    if not OLDEST.exists():
        pytest.skip("no .venv-oldest: make test makes it where a Python 3.11 is found")
    probe = (
        "import sys; from importlib.metadata import version; "
        "print(sys.version_info[:2], version('drake'))"
    )
    r = subprocess.run([str(OLDEST), "-c", probe], capture_output=True, text=True, timeout=60)
    assert r.stdout.split(maxsplit=2)[:2] == ["(3,", "11)"] and "1.51.1" in r.stdout, r.stdout
    r = subprocess.run(
        [str(OLDEST), "-m", "cake_drake.run", "--mode", "torque", "--out", "out"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    assert "goal reached: a on b on c on d on e" in r.stdout
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["success"] is True
    r = subprocess.run(
        [str(OLDEST), "-m", "cake_drake.train", "nowhere", "--out", "trained"],
        cwd=tmp_path, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "Python 3.12 or newer" in r.stderr and "3.11" in r.stderr
