"""Drawing a Drake Diagram: its Graphviz source rendered to SVG by the ``dot`` binary.

Drake describes any System as Graphviz text (``GetGraphvizString``); turning that into
a picture needs Graphviz's ``dot`` program (Debian/Ubuntu: ``apt-get install graphviz``).
The notebooks show the result inline with ``IPython.display.SVG``.
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Mapping

from pydrake.systems.framework import PortDataType, System

from cake_drake.errors import CakeDrakeError, InputError

#: How to get ``dot`` where it is missing, for the error message.
INSTALL_HINT = (
    "install Graphviz: apt-get install graphviz (Debian/Ubuntu), brew install graphviz "
    "(macOS) or conda install graphviz"
)


def graphviz_svg(source: str, dot: str = "dot", timeout_s: float = 60.0) -> str:
    """Render Graphviz ``source`` to SVG text with the ``dot`` program.

    ``dot`` is a program name looked up on PATH, or a path to the binary. Raises
    :class:`InputError` when it cannot be found or rejects the source.
    """
    exe = shutil.which(dot)
    if exe is None:
        raise InputError(
            f"Graphviz program {dot!r} not found on PATH; it draws the Diagram as SVG; "
            + INSTALL_HINT
        )
    # Not a group of our own (cake_drake.processes): subprocess.run kills `dot` on any
    # exception while it waits (the timeout, Ctrl-C or SIGTERM raised as an interrupt),
    # `dot` starts no children, and killed outright we leave it its input's end of file:
    # it draws one graph, then ends on its own.
    try:
        done = subprocess.run(
            [exe, "-Tsvg"],
            input=source,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            check=False,
        )
    except subprocess.TimeoutExpired:
        raise CakeDrakeError(
            f"{exe} did not finish drawing the graph within {timeout_s:g} s"
        ) from None
    if done.returncode != 0:
        first = next((ln for ln in done.stderr.splitlines() if ln.strip()), "no message")
        raise InputError(
            f"{exe} rejected the Graphviz source (exit code {done.returncode}): {first}"
        )
    return done.stdout


def diagram_svg(
    system: System,
    max_depth: int | None = 1,
    options: Mapping[str, str] | None = None,
    dot: str = "dot",
) -> str:
    """SVG of ``system`` (usually a Diagram): every subsystem and port named.

    ``max_depth`` limits how far nested diagrams are opened (0: one block; None: all);
    ``options`` are Drake's Graphviz options, e.g. ``{"plant/split": "I/O"}`` to draw
    the plant's inputs and outputs as two nodes so the feedback loop reads left to right.
    """
    source = system.GetGraphvizString(max_depth=max_depth, options=dict(options or {}))
    return graphviz_svg(source, dot)


def ports_text(system: System) -> str:
    """One line per port of ``system``: direction, name, and size or ``abstract``."""

    def kind(port) -> str:
        if port.get_data_type() == PortDataType.kAbstractValued:
            return "abstract"
        return f"vector[{port.size()}]"

    inputs = [system.get_input_port(i) for i in range(system.num_input_ports())]
    outputs = [system.get_output_port(i) for i in range(system.num_output_ports())]
    width = max((len(p.get_name()) for p in inputs + outputs), default=0)
    lines = [f"{system.get_name()} ({type(system).__name__})"]
    lines += [f"  input   {p.get_name():<{width}}  {kind(p)}" for p in inputs]
    lines += [f"  output  {p.get_name():<{width}}  {kind(p)}" for p in outputs]
    return "\n".join(lines)
