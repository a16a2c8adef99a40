"""The door every layer's implementation comes through: a registry name or ``module:attribute``.

A scenario names each layer's implementation (planner, action source, IK solver,
controller) either by a name from that layer's registry or as ``module:attribute`` of the
user's own code (``my_package.planners:llm_planner``, or ``examples.pid_controller:make``
for a file ``examples/pid_controller.py`` under the working folder). Shipped
implementations and a user's go through the same :func:`resolve`, so a plug-in is
checked, called and recorded exactly as the built-in ones are.
"""

from __future__ import annotations

import importlib
import math
import signal
import sys
import sysconfig
import threading
import time
import traceback
from collections.abc import Callable, Mapping
from pathlib import Path

from cake_drake.errors import (
    EXIT_BAD_INPUT,
    EXIT_EXECUTION_FAILED,
    CakeDrakeError,
    InputError,
)

#: Exit codes of a plug-in that fails: while the run is checked and built, and while it runs.
BEFORE, DURING = EXIT_BAD_INPUT, EXIT_EXECUTION_FAILED


def is_plugin(spec: str) -> bool:
    """True when ``spec`` names user code (``module:attribute``), not a registry entry.

    A registry name may carry an argument after ``@`` (``learned@DIR``, a folder that may
    hold a colon): ``@`` cannot appear in a module's name, so such a name is never a plug-in.
    """
    return ":" in spec and "@" not in spec.partition(":")[0]


def load_attribute(spec: str, what: str) -> object:
    """Import ``module:attribute``; one :class:`InputError` line naming what failed."""
    module_name, _, attribute = spec.partition(":")
    if not module_name or not attribute:
        raise InputError(
            f"{what} {spec!r}: a plug-in is written module:attribute "
            "(e.g. examples.pid_controller:make)"
        )
    cwd = str(Path.cwd())
    if cwd not in sys.path:  # user code beside the scenario, as `python -m` would find it
        sys.path.append(cwd)
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name and module_name.startswith(e.name):
            raise InputError(
                f"{what} {spec!r}: cannot import module {module_name!r} ({e})"
            ) from None
        raise failure(e, f"{what} {spec!r}: importing {module_name!r}", BEFORE) from None
    except (Exception, SystemExit) as e:  # noqa: BLE001 - the user's module failed importing
        raise failure(e, f"{what} {spec!r}: importing {module_name!r}", BEFORE) from None
    obj = module
    for part in attribute.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise InputError(
                f"{what} {spec!r}: module {module_name!r} has no attribute {attribute!r}"
            ) from None
    return obj


def resolve(
    spec: str,
    registry: Mapping[str, Callable],
    what: str,
    exit_code: int = BEFORE,
    budget: Callable[..., float | None] | None = None,
) -> Callable:
    """The factory named by ``spec``: a ``registry`` entry or a ``module:attribute``.

    A plug-in's factory comes back :func:`guarded`: whatever it raises is one line naming
    it, with ``exit_code``; ``budget(*args, **kwargs)`` gives a call's wall-clock budget.
    """
    if is_plugin(spec):
        factory = load_attribute(spec, what)
        if not callable(factory):
            raise InputError(f"{what} {spec!r} is not callable (a {type(factory).__name__})")
        return guard_factory(spec, what, factory, exit_code, budget)
    try:
        return registry[spec]
    except KeyError:
        raise InputError(
            f"unknown {what} {spec!r}; choose one of: {', '.join(registry)}, "
            "or module:attribute of your own"
        ) from None


def require(obj: object, spec: str, what: str, attributes: tuple[str, ...]) -> None:
    """Check that a plug-in's product has the protocol's ``attributes``; name what is missing."""
    missing = [a for a in attributes if not hasattr(obj, a)]
    if missing:
        raise InputError(
            f"{what} {spec!r} returned a {type(obj).__name__} without "
            f"{', '.join(missing)} (the {what} protocol needs {', '.join(attributes)})"
        )


# --- every call into user code goes through guarded() --------------------------------------


class PluginError(CakeDrakeError):
    """A plug-in raised, ended the program, returned garbage or overran its budget.

    ``trace`` is the full traceback, shown with ``--traceback`` (or
    ``CAKE_DRAKE_TRACEBACK=1``) for the plug-in's author; ``overran`` is the budget (s)
    when the plug-in overran it, and ``where`` the user's ``file:line`` it was stopped at.
    """

    def __init__(
        self,
        message: str,
        exit_code: int = BEFORE,
        trace: str | None = None,
        overran: float | None = None,
        where: str | None = None,
    ):
        super().__init__(message)
        self.exit_code = exit_code
        self.trace = trace
        self.overran = overran
        self.where = where


class _Overrun(BaseException):
    """Raised inside a plug-in at the end of its budget (not an Exception: a plug-in's own
    ``except Exception`` does not swallow it). ``owner`` is the :class:`budget` that ran
    out: a call guarded inside another budget reports only its own."""

    def __init__(self, owner: budget | None = None) -> None:
        super().__init__()
        self.owner = owner


_LIBRARY = tuple(
    str(Path(p).resolve())
    for p in {sysconfig.get_paths()[k] for k in ("stdlib", "platstdlib", "purelib", "platlib")}
)
_OURS = str(Path(__file__).resolve().parent)


def _is_user_file(filename: str) -> bool:
    try:
        path = str(Path(filename).resolve())
    except (OSError, ValueError):
        return False
    if path.startswith(_OURS + "/") or filename.startswith("<"):
        return False
    return not path.startswith(_LIBRARY)


def user_frame(tb) -> str | None:
    """``file:line`` of the innermost frame of the traceback that is the user's own code
    (not cake_drake, the standard library or an installed package)."""
    where = None
    for frame in traceback.extract_tb(tb):
        if _is_user_file(frame.filename):
            where = f"{frame.filename}:{frame.lineno}"
    return where


def failure(e: BaseException, label: str, exit_code: int, budget_s: float | None = None):
    """The :class:`PluginError` for ``e`` raised by the plug-in ``label`` names."""
    where = user_frame(e.__traceback__)
    at = f" at {where}" if where else ""
    trace = "".join(traceback.format_exception(e))
    if isinstance(e, _Overrun):
        message = f"{label} overran its budget of {budget_s:g} s{at}"
    elif isinstance(e, SystemExit):
        message = (
            f"{label} called sys.exit({e.code!r}){at}: a plug-in returns or raises, it does "
            "not end the program"
        )
    elif isinstance(e, RecursionError):
        message = f"{label} recursed without end (RecursionError){at}"
    else:
        text = (str(e).strip().splitlines() or [""])[0]
        message = f"{label} raised {type(e).__name__}{': ' + text if text else ''}{at}"
    overran = budget_s if isinstance(e, _Overrun) else None
    return PluginError(message, exit_code, trace, overran, where)


def guarded(
    label: str,
    fn: Callable,
    *args,
    exit_code: int = BEFORE,
    budget_s: float | None = None,
    **kwargs,
):
    """``fn(*args, **kwargs)`` for user code: whatever it raises (an exception, ``SystemExit``,
    endless recursion) or a budget it overruns becomes one :class:`PluginError` line naming
    ``label`` and the user's file:line. Ctrl-C stays an interrupt. The budget (wall clock)
    is kept in the main thread, inside any other that is running (:class:`budget`): an
    outer budget that ends first passes through, for its owner to report."""
    timer = budget(None if budget_s is None else max(budget_s, 1e-3))
    try:
        with timer:
            return fn(*args, **kwargs)
    except (KeyboardInterrupt, CakeDrakeError):
        raise
    except _Overrun as e:
        if e.owner is not timer:  # an outer budget ran out while this call was running
            raise
        raise failure(e, label, exit_code, budget_s) from None
    except (Exception, SystemExit) as e:  # noqa: BLE001 - user code
        raise failure(e, label, exit_code, budget_s) from None


def guard_factory(
    spec: str,
    what: str,
    factory: Callable,
    exit_code: int = BEFORE,
    budget: Callable[..., float | None] | None = None,
) -> Callable:
    """``factory`` wrapped so that every call to it is :func:`guarded` (for a plug-in);
    a shipped factory is returned as it is."""
    if not is_plugin(spec):
        return factory

    def call(*args, **kwargs):
        budget_s = budget(*args, **kwargs) if budget is not None else None
        return guarded(
            f"{what} {spec!r}", factory, *args, exit_code=exit_code, budget_s=budget_s, **kwargs
        )

    call.__wrapped__ = factory  # type: ignore[attr-defined]
    return call


def raised_in_simulation(
    e: BaseException, specs: Mapping[str, str], budget_s: float | None = None
) -> PluginError | None:
    """A :class:`PluginError` (exit 3) when ``e``, out of a simulation, came from a plug-in's
    code; ``specs`` maps each plug-in's ``module:attribute`` to what it is. None when the
    exception did not come from user code."""
    where = user_frame(e.__traceback__)
    if where is None:
        if isinstance(e, _Overrun):  # it ended outside the plug-ins' own code
            return failure(e, "the simulation with " + ", ".join(specs), DURING, budget_s)
        return None
    filename = where.rsplit(":", 1)[0]
    label = "a plug-in"
    for spec, what in specs.items():
        module = sys.modules.get(spec.partition(":")[0])
        file = getattr(module, "__file__", None)
        if file and Path(file).resolve() == Path(filename).resolve():
            label = f"{what} {spec!r}"
            break
    return failure(e, label, DURING, budget_s)


class budget:
    """A wall-clock budget around a block that runs plug-ins inside Drake's callbacks
    (``with budget(30): simulator.AdvanceTo(t)``): at its end :class:`_Overrun` is raised
    in whatever Python runs then. None when ``seconds`` is None or outside the main thread.

    Budgets nest, each keeping its own deadline: one real-time timer (``SIGALRM``) is set
    for the earliest deadline of all those running, and the overrun raised names the
    innermost budget that has run out. A timer set by someone else before the outermost
    budget began is kept as the outermost deadline: its handler is called when it falls
    due, and it is set again (what is left of it, and its interval) when the last budget
    ends.
    """

    _running: list[budget] = []  # the budgets running now, outermost first
    _foreign: list = []  # [handler, deadline or None, interval] of a timer set before ours

    def __init__(self, seconds: float | None) -> None:
        self.seconds = seconds
        self.timed = False
        self.deadline = math.inf

    def __enter__(self) -> budget:
        self.timed = (
            self.seconds is not None and threading.current_thread() is threading.main_thread()
        )
        if not self.timed:
            return self
        now = time.monotonic()
        if not budget._running:
            left, interval = signal.getitimer(signal.ITIMER_REAL)
            handler = signal.signal(signal.SIGALRM, _budget_alarm)
            budget._foreign[:] = [handler, now + left if left > 0 else None, interval]
        self.deadline = now + self.seconds
        budget._running.append(self)
        _arm()
        return self

    def __exit__(self, *exc) -> None:
        if not self.timed:
            return
        budget._running.remove(self)
        if budget._running:
            _arm()
            return
        signal.setitimer(signal.ITIMER_REAL, 0)
        handler, deadline, interval = budget._foreign
        signal.signal(signal.SIGALRM, handler)
        if deadline is not None:  # someone else's timer goes on where it was
            signal.setitimer(signal.ITIMER_REAL, max(deadline - time.monotonic(), 1e-6), interval)


def _arm() -> None:
    """Set the real-time timer for the earliest deadline of the budgets running (and of a
    foreign timer kept under them)."""
    deadlines = [b.deadline for b in budget._running]
    if budget._foreign and budget._foreign[1] is not None:
        deadlines.append(budget._foreign[1])
    signal.setitimer(signal.ITIMER_REAL, max(min(deadlines) - time.monotonic(), 1e-6))


def _budget_alarm(signum, frame) -> None:
    now = time.monotonic()
    due = [b for b in budget._running if b.deadline <= now]
    if due:
        raise _Overrun(due[-1])  # the innermost that ran out
    foreign = budget._foreign
    if foreign and foreign[1] is not None and foreign[1] <= now:
        handler, _, interval = foreign
        foreign[1] = now + interval if interval > 0 else None
        _arm()
        if callable(handler):
            handler(signum, frame)
        elif handler == signal.SIG_DFL:  # SIGALRM's default: the end of the process
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.raise_signal(signal.SIGALRM)
        return
    _arm()  # early by a hair: set again for what is left
