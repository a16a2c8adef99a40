"""Process groups this process owns: started here, and gone when this process is.

A child started with ``start_new_session=True`` is safe from the terminal's Ctrl-C, but
nothing ends it when its caller ends: an interrupt, a ``timeout``'s SIGTERM, a cancelled
CI job or a SIGKILL leaves it (and its own children: Fast Downward's driver runs translate,
then the search) re-parented to init, running until it is done or next writes to its
gone caller's pipe (a search on a plateau may write nothing for hours). :func:`owned`
starts ``cmd`` under a small guard process instead, which leads the new session and its
process group, runs ``cmd`` in that group and passes its exit status on. The group ends:

- when the caller stops waiting for any reason (an exception, Ctrl-C or SIGTERM raised as
  :class:`KeyboardInterrupt` by :mod:`cake_drake.errors`' handlers): :func:`stop` kills
  the whole group before the exception goes on;
- at normal interpreter exit, for a group still running (an ``atexit`` hook);
- when the caller dies in any other way, SIGKILL included, where nothing of it runs: the
  kernel signals the guard (Linux's ``PR_SET_PDEATHSIG``), which kills the whole group.
  The signal comes when the *thread* that started the guard ends, so start a group from
  the thread that waits for it;
- when the guard itself is sent SIGTERM, SIGINT or SIGHUP.

When ``cmd`` ends by itself, the guard kills whatever it left behind in the group before
passing its status on. Plain standard library: the guard runs this file as a script
(``python -I -S``), so it imports nothing of the project's.

:func:`temporaries_in` is the same care for files: what a call leaves in the temporary
folder goes in one the caller removes.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence

#: The signals the guard answers by killing its group (the death signal is the first).
_GUARD_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
_PR_SET_PDEATHSIG = 1

#: Guards started here and not yet stopped: the ``atexit`` hook ends what still runs.
_running: set[subprocess.Popen] = set()


def start(cmd: Sequence[str], **popen_kwargs) -> subprocess.Popen:
    """Start ``cmd`` in a new session and process group owned by this process.

    The :class:`subprocess.Popen` returned is the guard's: its ``pid`` is the group's
    id, its ``returncode`` is ``cmd``'s, and its pipes are ``cmd``'s (the keywords are
    Popen's, given to the guard, whose ``cmd`` inherits its cwd, environment and standard
    streams). Call :func:`stop` when done, or use :func:`owned`. Raises
    FileNotFoundError, as Popen does, when ``cmd[0]`` is not found.
    """
    for key in ("start_new_session", "process_group", "preexec_fn"):
        if key in popen_kwargs:
            raise TypeError(f"processes.start sets the session itself; drop {key}=")
    cmd = [os.fspath(a) for a in cmd]
    exe = cmd[0]
    if os.sep not in exe:  # looked up on PATH, as Popen does
        path = (popen_kwargs.get("env") or os.environ).get("PATH", os.defpath)
        exe = shutil.which(exe, path=path) or exe
    exe = os.path.join(os.fspath(popen_kwargs.get("cwd") or os.getcwd()), exe)
    if not os.access(exe, os.X_OK) or os.path.isdir(exe):
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), cmd[0])
    guard = [sys.executable, "-I", "-S", os.path.abspath(__file__), str(os.getpid()), exe]
    proc = subprocess.Popen(guard + cmd[1:], start_new_session=True, **popen_kwargs)
    _running.add(proc)
    return proc


def stop(proc: subprocess.Popen) -> None:
    """Kill ``proc``'s whole group and reap the guard (unless it was reaped already: then
    the group is gone, and its id may be another's); close its pipes. The kill comes
    first, so an interrupt landing in here leaves at most a guard to reap."""
    if proc.returncode is None:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    _running.discard(proc)
    for stream in (proc.stdin, proc.stdout, proc.stderr):
        if stream is not None:
            with contextlib.suppress(OSError):
                stream.close()


@contextlib.contextmanager
def owned(cmd: Sequence[str], **popen_kwargs) -> Iterator[subprocess.Popen]:
    """:func:`start` ``cmd``; whatever ends the ``with`` block (its end, an exception,
    an interrupt), the group is gone after it (:func:`stop`)."""
    proc = start(cmd, **popen_kwargs)
    try:
        yield proc
    finally:
        stop(proc)


@contextlib.contextmanager
def temporaries_in(folder: str | None) -> Iterator[None]:
    """While inside, Python's temporary files (:mod:`tempfile`'s, in this process) go in
    ``folder`` (``None``: where they would anyway): a library that leaves its own behind,
    or a run killed before it removes its, leaves them in a folder its caller removes."""
    was, tempfile.tempdir = tempfile.tempdir, folder or tempfile.tempdir
    try:
        yield
    finally:
        tempfile.tempdir = was


@atexit.register
def _stop_all() -> None:
    """Normal interpreter exit: every group still running ends with this process."""
    for proc in list(_running):
        if proc.poll() is None:
            stop(proc)
        _running.discard(proc)


# --- the guard (this file run as a script) ---------------------------------------------


def _others_in_group() -> list[int]:
    """The live processes of this process's group, this one left out (Linux's /proc)."""
    me, group = os.getpid(), os.getpgrp()
    found = []
    try:
        names = os.listdir("/proc")
    except OSError:  # no /proc (not Linux): nothing to sweep
        return found
    for name in names:
        if not name.isdigit() or int(name) == me:
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as f:
                fields = f.read().rpartition(b")")[2].split()
        except OSError:  # ended meanwhile
            continue
        if len(fields) > 2 and int(fields[2]) == group and fields[0] != b"Z":
            found.append(int(name))
    return found


def _guard(parent: int, cmd: list[str]) -> None:
    """Run ``cmd`` in this group; end the group with this process's parent, on a signal,
    and once ``cmd`` ended (what it left behind); exit as ``cmd`` did."""

    def end_group(signum, frame) -> None:
        os.killpg(0, signal.SIGKILL)

    for s in _GUARD_SIGNALS:
        signal.signal(s, end_group)
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, _GUARD_SIGNALS[0])
    except (OSError, AttributeError):  # not Linux: the caller's own stop() is left
        pass
    if os.getppid() != parent:  # the caller died before the death signal was set
        os._exit(128 + signal.SIGKILL)
    defaults = (*_GUARD_SIGNALS, signal.SIGPIPE, signal.SIGXFSZ)  # as Popen's restore_signals
    try:
        child = os.posix_spawn(cmd[0], cmd, os.environ, setsigdef=defaults)
    except OSError as e:
        os.write(2, f"{cmd[0]}: {e.strerror}\n".encode())
        os._exit(127)
    _, status = os.waitpid(child, 0)
    for _ in range(3):  # what cmd left behind; they could start more while being killed
        others = _others_in_group()
        for pid in others:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGKILL)
        if not others:
            break
    if os.WIFSIGNALED(status):  # the caller sees the same signal (Popen: -signum)
        import resource

        sig = os.WTERMSIG(status)
        resource.setrlimit(resource.RLIMIT_CORE, (0, resource.getrlimit(resource.RLIMIT_CORE)[1]))
        signal.signal(sig, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {sig})
        os.kill(os.getpid(), sig)
    os._exit(os.WEXITSTATUS(status) if os.WIFEXITED(status) else 1)


if __name__ == "__main__":
    _guard(int(sys.argv[1]), sys.argv[2:])
