"""A plug-in is user code: whatever it does, the user gets one line and a documented code.

Each hostile plug-in is a small module written into the test's folder and named on the
real command line, as a user would: it raises, returns garbage, recurses without end,
ends the program, or sleeps past its budget.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import ROOT

PLUGIN = """
import sys
import time

import numpy as np

from cake_drake.geometric.ik import DrakeIk
from cake_drake.symbolic import GroundAction


def raises(problem, time_limit):
    return 1 / 0


def an_int(problem, time_limit):
    return 7


def strings(problem, time_limit):
    return ["(unstack a b)", "(put-down a)"]


def endless(problem, time_limit):
    return endless(problem, time_limit)


def exits(problem, time_limit):
    sys.exit(0)


def sleeps(problem, time_limit):
    time.sleep(600)


def invalid(problem, time_limit):
    return [GroundAction("stack", ("a", "e"))]


class Garbage:
    name = "garbage"

    def __init__(self, kinematics, seed, answer):
        self.inner = DrakeIk(kinematics, seed)
        self.answer = answer

    def solve(self, X_WG, q_seed):
        q = self.inner.solve(X_WG, q_seed)
        return self.answer(q)


def ik_nan(kinematics, seed):
    return Garbage(kinematics, seed, lambda q: np.full(7, np.nan))


def ik_far(kinematics, seed):
    return Garbage(kinematics, seed, lambda q: np.full(7, 1e6))


def ik_shape(kinematics, seed):
    return Garbage(kinematics, seed, lambda q: q[:3])


def ik_raises(kinematics, seed):
    def boom(q):
        raise ValueError("no luck today")
    return Garbage(kinematics, seed, boom)


def ik_exits(kinematics, seed):
    return Garbage(kinematics, seed, lambda q: sys.exit(0))


def ik_factory_raises(kinematics, seed):
    raise RuntimeError("cannot build")


def controller_raises(**options):
    raise KeyError("gains")
"""


def run(*args: str, cwd: Path, command: str = "run"):
    return subprocess.run(
        [sys.executable, "-m", f"cake_drake.{command}", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": f"{cwd}{os.pathsep}{ROOT}"},
    )


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "hostile.py").write_text(PLUGIN)
    return tmp_path


def one_line(r, code: int, *words: str) -> None:
    assert r.returncode == code, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    lines = [line for line in r.stderr.splitlines() if not line.startswith("simulating")]
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], lines[0]


LINE = {
    "raises": "hostile.py:12",
    "endless": "hostile.py:24",
    "exits": "hostile.py:28",
    "sleeps": "hostile.py:32",
}


@pytest.mark.parametrize(
    "planner, words",
    [
        ("raises", ["raised ZeroDivisionError: division by zero", LINE["raises"]]),
        ("an_int", ["returned int", "a planner returns a Plan"]),
        ("strings", ["returned a list holding str"]),
        ("endless", ["recursed without end", LINE["endless"]]),
        ("exits", ["called sys.exit(0)", LINE["exits"]]),
    ],
)
def test_a_hostile_planner_is_one_line_and_exit_2_with_nothing_written(folder, planner, words):
    r = run("--planner", f"hostile:{planner}", "--time-limit", "1", "--out", "o", cwd=folder)
    one_line(r, 2, f"planner 'hostile:{planner}'", *words)
    assert not (folder / "o").exists()


@pytest.mark.parametrize("command", ["run", "plan"])
def test_a_planner_plugin_that_overruns_the_time_limit_has_given_up_exit_1(folder, command):
    """As a built-in planner that gives up at --time-limit: no plan (1), said as what it is."""
    r = run("--planner", "hostile:sleeps", "--time-limit", "1", cwd=folder, command=command)
    one_line(
        r, 1, "no plan found for problem", "within the 1 s time limit",
        "planner 'hostile:sleeps' overran its time limit", LINE["sleeps"],
    )  # fmt: skip
    assert not (folder / "outputs").exists()


def test_a_plugin_call_keeps_its_own_budget_inside_a_running_one():
    """The run's step timer is running: a plug-in's shorter budget still ends it, named."""
    import time

    from cake_drake.plugins import DURING, PluginError, budget, guarded

    with budget(600), pytest.raises(PluginError) as e:
        guarded("motion planner 'slow:make'", time.sleep, 30, exit_code=DURING, budget_s=0.5)
    assert str(e.value).startswith("motion planner 'slow:make' overran its budget of 0.5 s")
    assert e.value.exit_code == DURING


def test_an_outer_budget_that_ends_first_is_its_own_not_the_plugins():
    import time

    from cake_drake.plugins import _Overrun, budget, guarded

    with pytest.raises(_Overrun) as e, budget(0.3) as outer:
        guarded("policy 'p:make'", time.sleep, 30, budget_s=60)
    assert e.value.owner is outer  # not a PluginError blaming the call inside
    with pytest.raises(_Overrun) as e, budget(0.3) as outer:
        guarded("policy 'p:make'", lambda: None, budget_s=60)
        time.sleep(30)  # the outer deadline holds after the inner call ended
    assert e.value.owner is outer


def test_a_timer_set_before_the_budgets_is_kept():
    import signal
    import time

    from cake_drake.plugins import budget

    class Rang(Exception):
        pass

    def ring(signum, frame):
        raise Rang()

    previous = signal.signal(signal.SIGALRM, ring)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.3)
        with pytest.raises(Rang), budget(600):
            time.sleep(30)  # someone else's timer falls due inside the budget
        assert signal.getsignal(signal.SIGALRM) is ring
        signal.setitimer(signal.ITIMER_REAL, 0.3)
        with budget(600):
            pass
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0  # set again where it was
        with pytest.raises(Rang):
            time.sleep(30)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def test_an_invalid_plan_from_a_planner_is_no_plan(folder):
    r = run("--planner", "hostile:invalid", "--out", "o", cwd=folder)
    one_line(r, 1, "not a valid plan")


@pytest.mark.parametrize(
    "ik, words",
    [
        ("ik_nan", ["returned non-finite angles"]),
        ("ik_far", ["joint 1 at 1e+06 rad, outside its limits"]),
        ("ik_shape", ["an array of shape (3,), not 7 joint angles"]),
        ("ik_raises", ["raised ValueError: no luck today", "hostile.py:"]),
        ("ik_exits", ["called sys.exit(0)", "hostile.py:"]),
    ],
)
def test_a_hostile_ik_solver_is_one_line_and_exit_3(folder, ik, words):
    r = run("--ik", f"hostile:{ik}", "--out", "o", "--quiet", cwd=folder)
    one_line(r, 3, f"IK solver 'hostile:{ik}'", *words)
    assert not (folder / "o").exists()


def test_a_failing_factory_is_exit_2(folder):
    r = run("--ik", "hostile:ik_factory_raises", "--out", "o", "--quiet", cwd=folder)
    one_line(r, 2, "IK solver 'hostile:ik_factory_raises' raised RuntimeError: cannot build")


def test_a_failing_controller_factory_is_exit_2(folder):
    (folder / "s.yaml").write_text(
        "controller: !CustomController {factory: hostile:controller_raises}\n"
    )
    r = run("--scenario", "s.yaml", "--out", "o", cwd=folder)
    one_line(r, 2, "controller factory 'hostile:controller_raises' raised KeyError", "hostile.py:")


def test_a_module_that_exits_while_importing_is_not_a_success(folder):
    (folder / "quits.py").write_text("import sys\nsys.exit(0)\n")
    r = run("--planner", "quits:anything", "--out", "o", cwd=folder)
    one_line(r, 2, "called sys.exit(0)", "quits.py:2")


@pytest.mark.parametrize("how", ["flag", "environment"])
def test_the_whole_traceback_is_there_for_the_plugins_author(folder, how):
    args = ["--planner", "hostile:raises", "--out", "o"]
    if how == "flag":
        r = run(*args, "--traceback", cwd=folder)
    else:
        os.environ["CAKE_DRAKE_TRACEBACK"] = "1"
        try:
            r = run(*args, cwd=folder)
        finally:
            del os.environ["CAKE_DRAKE_TRACEBACK"]
    assert r.returncode == 2
    assert "Traceback (most recent call last)" in r.stderr and "1 / 0" in r.stderr
    assert r.stderr.splitlines()[-1].startswith("error: planner 'hostile:raises' raised")


def test_plan_takes_a_plugin_planner_as_run_does(folder):
    (folder / "mine.py").write_text(
        "from cake_drake.symbolic import solve_problem\n"
        "def planner(problem, time_limit):\n"
        "    return solve_problem(problem, 'astar-lmcut', time_limit).actions\n"
    )
    r = run("--planner", "mine:planner", cwd=folder, command="plan")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == "(unstack a b)"
    r = run("--planner", "hostile:raises", cwd=folder, command="plan")
    one_line(r, 2, "planner 'hostile:raises' raised ZeroDivisionError", LINE["raises"])


SOURCES = """
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from cake_drake.systems import PlanSource
from cake_drake.systems.plan_source import ActionCommand


class WrongType(LeafSystem):
    def __init__(self):
        super().__init__()
        self.DeclareVectorInputPort("actions_done", 1)
        self.DeclareAbstractOutputPort(
            "action", lambda: AbstractValue.Make(3), lambda context, out: out.set_value(3)
        )


class Garbage(PlanSource):
    def _calc_action(self, context, output):
        output.set_value(ActionCommand(0, "(unstack a b)"))


class Sleeps(PlanSource):
    def _calc_action(self, context, output):
        import time

        time.sleep(600)


def sleeps(context):
    return Sleeps(context.actions)


def wrong_type(context):
    return WrongType()


def garbage(context):
    source = Garbage(context.actions)
    return source
"""


def test_an_action_source_whose_action_is_not_a_command_is_exit_3(folder):
    (folder / "sources.py").write_text(SOURCES)
    r = run("--action-source", "sources:wrong_type", "--out", "o", "--quiet", cwd=folder)
    one_line(r, 3, "the action source gave 3; it gives an ActionCommand")


def test_an_action_source_giving_garbage_is_one_line_and_exit_3(folder):
    (folder / "sources.py").write_text(SOURCES)
    r = run("--action-source", "sources:garbage", "--out", "o", "--quiet", cwd=folder)
    one_line(r, 3, "the action source gave ActionCommand(index=0, action='(unstack a b)')")


def test_an_action_source_that_hangs_inside_the_simulation_ends_at_its_budget(folder):
    (folder / "sources.py").write_text(SOURCES)
    (folder / "s.yaml").write_text(
        "reference: {action_source: sources:sleeps}\nsimulation: {step_budget_s: 1}\n"
    )
    r = run("--scenario", "s.yaml", "--out", "o", "--quiet", cwd=folder)
    one_line(r, 3, "action source 'sources:sleeps' overran its budget of 1 s", "sources.py:")
