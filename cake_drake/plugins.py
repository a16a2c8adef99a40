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
import sys
from collections.abc import Callable, Mapping
from pathlib import Path

from cake_drake.errors import InputError


def is_plugin(spec: str) -> bool:
    """True when ``spec`` names user code (``module:attribute``), not a registry entry."""
    return ":" in spec


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
    except ImportError as e:
        raise InputError(f"{what} {spec!r}: cannot import module {module_name!r} ({e})") from None
    except Exception as e:  # noqa: BLE001 - the user's module failed while importing
        raise InputError(
            f"{what} {spec!r}: importing {module_name!r} failed: {type(e).__name__}: {e}"
        ) from None
    obj = module
    for part in attribute.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise InputError(
                f"{what} {spec!r}: module {module_name!r} has no attribute {attribute!r}"
            ) from None
    return obj


def resolve(spec: str, registry: Mapping[str, Callable], what: str) -> Callable:
    """The factory named by ``spec``: a ``registry`` entry or a ``module:attribute``."""
    if is_plugin(spec):
        factory = load_attribute(spec, what)
        if not callable(factory):
            raise InputError(f"{what} {spec!r} is not callable (a {type(factory).__name__})")
        return factory
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
