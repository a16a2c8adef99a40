"""One exception hierarchy for the whole project.

Every message names the input, the place (``file:line[:col]`` where there is one)
and what would be valid. The command-line tools turn these into one line on
stderr and the exit code stored on the class.
"""

from __future__ import annotations

import errno
import os
import sys
from collections.abc import Callable

#: Documented exit codes of every command-line tool.
EXIT_OK = 0
EXIT_NO_PLAN = 1  # no plan (proved or limit reached); an invalid plan; a plan that fails
EXIT_BAD_INPUT = 2  # unreadable or malformed input, bad options
EXIT_EXECUTION_FAILED = 3  # the plan could not be executed in the simulated world
EXIT_OUTPUT_FAILED = 4  # the outputs could not be written (full disk, read-only folder)
EXIT_INTERRUPTED = 130  # Ctrl-C or SIGTERM: stopped, nothing half-written left behind

#: Set (to anything but 0) to see a failing plug-in's whole traceback, as ``--traceback`` does.
TRACEBACK_ENV = "CAKE_DRAKE_TRACEBACK"


class CakeDrakeError(Exception):
    """Base class: a problem the user can act on, with a one-line message."""

    exit_code = EXIT_BAD_INPUT


class InputError(CakeDrakeError):
    """A file or option that cannot be used as given (missing, unreadable, malformed)."""

    exit_code = EXIT_BAD_INPUT


class PddlError(InputError):
    """PDDL text that does not parse or does not fit its domain."""


class NoPlanError(CakeDrakeError):
    """The planner found no plan: proved unsolvable, or it gave up at a limit."""

    exit_code = EXIT_NO_PLAN


class ExecutionError(CakeDrakeError):
    """The plan could not be carried out by the robot (IK failure, goal not reached)."""

    exit_code = EXIT_EXECUTION_FAILED


class OutputError(CakeDrakeError):
    """The outputs could not be written (a full disk, a read-only folder): none were."""

    exit_code = EXIT_OUTPUT_FAILED


class IkError(ExecutionError):
    """Inverse kinematics found no joint configuration for a named waypoint."""


def quiet_interrupts() -> None:
    """A command's first act, before its heavy imports (pydrake, the CLI): Ctrl-C or
    SIGTERM while it starts ends it with the documented line and 130, never a traceback
    from inside an import. :func:`run_cli` takes over once the command runs.

    Every command gets it without a line of its own: the package's ``__init__``, which
    runs before any ``python -m cake_drake.<command>`` module and before the
    ``cake-drake`` console script imports the CLI, calls this when the process was started
    as one of them (:func:`cake_drake.started_as_command`).
    """
    import signal

    _a_command[:] = [True]
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, _interrupted_at_start)


#: Whether this process is a command (:func:`quiet_interrupts` ran): only a command, which
#: ends once :func:`run_cli` returns, ignores interrupts after the one that stopped it.
_a_command: list[bool] = []


#: Whether :func:`run_cli` has started a command's main (after it, an interrupt that
#: reaches :func:`_interrupted_at_start` comes while the interpreter ends).
_main_started: list[bool] = []


def _interrupted_at_start(signum, frame) -> None:
    """Nothing has been written before a command's main starts: say so, end at once."""
    import signal

    _ignore_interrupts()
    if not _main_started:
        how = " by SIGTERM" if signum == signal.SIGTERM else ""
        try:
            os.write(2, f"error: interrupted{how}; nothing was written\n".encode())
        except OSError:  # no standard error: the exit code says it
            pass
    os._exit(EXIT_INTERRUPTED)


def _ignore_interrupts() -> None:
    """A command that has decided to end as interrupted (130) ignores any interrupt after
    that one: the interpreter's teardown puts the default handlers back, and an interrupt
    arriving then (a second Ctrl-C, or one delivered late) killed the process by the
    signal (-2) after it had printed its line."""
    import signal

    for s in (signal.SIGINT, signal.SIGTERM):
        try:
            signal.signal(s, signal.SIG_IGN)
        except ValueError:  # not the main thread
            pass


#: The signal that stopped the run, once one has: an interrupt raised inside a Drake
#: callback can come back out of it as another exception (pybind11 reports a failed
#: argument conversion as a TypeError), and is an interrupt all the same.
_signalled: list[str] = []


def _terminate(signum, frame) -> None:
    import signal

    name = signal.Signals(signum).name
    _signalled.append(name)
    raise KeyboardInterrupt(name)


#: How long after an interrupt was dropped it is sent again, and the timers that will.
REDELIVER_S = 0.05
_redelivery: list = []


def _redeliver_swallowed(previous: Callable) -> Callable:
    """An ``sys.unraisablehook`` that sends an interrupt again when it landed where Python
    cannot raise (a weak reference's callback, as the import system's locks have, or a
    ``__del__``): Python prints it and carries on, and the command ran to its end."""

    def hook(unraisable) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt) and _signalled:
            import signal
            import threading

            # Sent again a moment later, from another thread, so that its handler runs in
            # the main thread's own code and not in here, where it would be dropped again.
            again = (os.getpid(), signal.Signals[_signalled[-1]])
            timer = threading.Timer(REDELIVER_S, os.kill, again)
            timer.daemon = True
            _redelivery.append(timer)
            timer.start()
            return
        previous(unraisable)

    return hook


def run_cli(main: Callable[[list[str] | None], int], argv: list[str] | None = None) -> int:
    """Call ``main`` and turn every way it can stop into one line and a documented code.

    :class:`CakeDrakeError` -> its message and exit code; Ctrl-C and SIGTERM ->
    "interrupted", 130 (the ``finally`` blocks on the way out remove anything staged);
    an ``OSError`` nothing else caught (a full disk mid-write) -> one line, 4.
    """
    import signal

    _reopen_closed_streams()
    caught = (signal.SIGTERM, signal.SIGINT)
    previous = {s: signal.getsignal(s) for s in caught}
    try:
        for s in caught:
            signal.signal(s, _terminate)
    except ValueError:  # not the main thread: leave signals alone
        previous = {}
    _signalled.clear()
    _main_started[:] = [True]
    previous_hook = sys.unraisablehook
    sys.unraisablehook = _redeliver_swallowed(previous_hook)
    given = sys.argv[1:] if argv is None else argv
    show_trace = "--traceback" in given or os.environ.get(TRACEBACK_ENV, "") not in ("", "0")
    try:
        return main(argv)
    except CakeDrakeError as e:
        trace = getattr(e, "trace", None)
        if trace and show_trace:  # a plug-in's failure, for its author
            print(trace, end="", file=sys.stderr)
        print(f"error: {one_line(str(e))}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt as e:  # the signal that came, however a library re-raised it
        return _interrupted(_signalled[0] if _signalled else str(e))
    except BrokenPipeError:
        # The reader went away (e.g. `| head`): stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_OK
    except OSError as e:
        if _signalled:
            return _interrupted(_signalled[0])
        if e.errno == errno.ENAMETOOLONG:  # a name the user gave, at a door not checked
            print(f"error: {one_line(shown_path(e.filename or ''))}: {e.strerror}", file=sys.stderr)
            return EXIT_BAD_INPUT
        where = f"{e.filename}: " if e.filename else ""
        print(f"error: {where}{e.strerror or e}; nothing was written", file=sys.stderr)
        return EXIT_OUTPUT_FAILED
    except Exception:
        if _signalled:  # the interrupt, reported by the callback it landed in as this
            return _interrupted(_signalled[0])
        raise
    finally:
        sys.unraisablehook = previous_hook
        while _redelivery:  # the command has stopped: nothing more to send
            _redelivery.pop().cancel()
        for s, handler in previous.items():
            signal.signal(s, handler)
        if _signalled and _a_command:  # the command ends now: as interrupted, 130
            _ignore_interrupts()


#: Control characters as they are written in an error line: a newline or a carriage return
#: in a path (a file's name may hold one) must not split the line or overwrite it.
_ESCAPED = {c: f"\\x{c:02x}" for c in (*range(9), *range(11, 32), 127)} | {10: "\\n", 13: "\\r"}


def shown_path(path: str) -> str:
    """``path`` as an error line shows it: a long one cut in the middle."""
    path = os.fsdecode(path)
    return path if len(path) <= 60 else f"{path[:40]}...{path[-16:]}"


def one_line(message: str) -> str:
    """``message`` with its control characters escaped, so that it prints as one line."""
    return message.translate(_ESCAPED)


def _reopen_closed_streams() -> None:
    """Standard output or error closed by the caller (``>&-``): what would be printed there
    goes nowhere, and the command's work and exit code are unchanged."""
    for name, fd in (("stdout", 1), ("stderr", 2)):
        try:
            os.fstat(fd)
        except OSError:
            os.dup2(os.open(os.devnull, os.O_WRONLY), fd)  # the descriptor, for children too
            setattr(sys, name, open(fd, "w", closefd=False))  # noqa: SIM115
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "w", closefd=False))  # noqa: SIM115


def _close_progress_bars() -> None:
    """Erase and close every progress bar still open (tqdm's, as LeRobot's training and
    loading draw them), so that the last line a user reads is the error, on a line of its
    own, and no bar is drawn after it."""
    std = sys.modules.get("tqdm.std")
    if std is None:
        return
    for bar in list(getattr(std.tqdm, "_instances", ())):
        try:
            bar.leave = False  # closing erases the bar's line instead of drawing it again
            bar.close()
            bar.disable = True
        except Exception:  # noqa: BLE001 - a bar half torn down: nothing more to draw
            pass


def _interrupted(name: str) -> int:
    how = " by SIGTERM" if name == "SIGTERM" else ""
    _close_progress_bars()
    print(f"error: interrupted{how}; nothing was written", file=sys.stderr)
    return EXIT_INTERRUPTED


def exit_now(code: int) -> None:
    """End a command whose work is done and whose files are all written, skipping the
    interpreter's teardown: freeing a simulated world object by object, and every module
    of pydrake, costs a run ~0.2 s and changes nothing. Standard output and error are
    flushed first. For commands that start no threads or processes of their own that
    outlive them (helpers are joined before this; a sweep's are not, so it exits normally).
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):  # a closed pipe, a closed stream: nothing to keep
            pass
    os._exit(code)
