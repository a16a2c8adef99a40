"""What the commands' parsers share: usage errors as one line, ``--set``, ``--ray``,
``--workers`` and ``--time-limit`` checked the same way everywhere."""

from __future__ import annotations

import argparse
import os

from cake_drake.errors import InputError


class CliParser(argparse.ArgumentParser):
    """argparse, but a usage error is one :class:`InputError` line (exit 2), not usage text.
    Every command takes ``--traceback`` (read by :func:`cake_drake.errors.run_cli`)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.add_argument(
            "--traceback",
            action="store_true",
            help="when a plug-in fails, show its whole traceback (or set CAKE_DRAKE_TRACEBACK=1)",
        )

    def error(self, message: str):  # type: ignore[override]
        raise InputError(f"{self.prog}: {message} (see --help)")


def add_ray_flag(p: argparse.ArgumentParser) -> None:
    """``--ray [ADDRESS]``: episodes on Ray (``record``, ``evaluate``, ``train --dagger``)."""
    p.add_argument(
        "--ray",
        nargs="?",
        const="",
        metavar="ADDRESS",
        help="episodes on Ray: a local instance, or the cluster at ADDRESS (auto | HOST:PORT)",
    )


def add_set_flag(p: argparse.ArgumentParser, what: str = "the scenario") -> None:
    """``--set section.field=VALUE``, repeatable: any field of ``what``, from the command
    line (:func:`cake_drake.scenario.with_settings`)."""
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.FIELD=VALUE",
        help=f"set one field of {what}, the value read as YAML (e.g. --set "
        "perception.estimator=depth --set world.cube_mass_kg=0.5); repeatable",
    )


def ray_engine(address: str | None, workers: int):
    """The Ray engine ``--ray`` asks for (None without it): checked before any work."""
    if address is None:
        return None
    from cake_drake.sweeps import RayCluster

    return RayCluster(address or None, None if address else workers)


def worker_count(n: int | None) -> int:
    """``--workers N``: at least 1; without it, one worker per core this process may use."""
    if n is not None and n < 1:
        raise InputError(f"--workers {n}: at least 1")
    return n or len(os.sched_getaffinity(0))


def check_time_limit(value: float | None) -> float | None:
    """A planner time limit from a flag: a positive, finite number of seconds (or none)."""
    import math

    if value is not None and not (math.isfinite(value) and value > 0):
        raise InputError(
            f"--time-limit {value:g}: the time limit must be a positive number of seconds"
        )
    return value
