"""The notebooks run headless, error-free, in test mode; git holds them with the outputs
of their current code (``notebooks/refresh.py``, ``make notebooks``).

Each notebook is executed with nbclient in a fresh temporary working directory with
``CAKE_DRAKE_QUICK=1`` (shorter simulations) and ``MPLBACKEND=Agg``. The helper that
draws the Diagram (:mod:`cake_drake.outputs.graph`) is tested here too.
"""

from __future__ import annotations

import shutil

import nbformat
import pytest

from cake_drake.errors import InputError
from cake_drake.outputs.graph import diagram_svg, graphviz_svg, ports_text
from tests.helpers import ROOT

NOTEBOOKS_DIR = ROOT / "notebooks"
NOTEBOOKS = ("01_symbolic", "02_diagram", "03_computed_torque", "04_recovery", "05_policy")

needs_dot = pytest.mark.skipif(shutil.which("dot") is None, reason="Graphviz dot not installed")


def _read(name: str) -> nbformat.NotebookNode:
    return nbformat.read(NOTEBOOKS_DIR / f"{name}.ipynb", as_version=4)


def test_every_notebook_is_listed():
    assert sorted(p.stem for p in NOTEBOOKS_DIR.glob("*.ipynb")) == sorted(NOTEBOOKS)


def _refresh_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("refresh", NOTEBOOKS_DIR / "refresh.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_is_stored_with_the_outputs_of_its_code(name):
    nb = _read(name)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, f"{name} has no code cells"
    assert any(c.outputs for c in code), f"{name} is stored without outputs"
    assert _refresh_module().problems(nb) == [], f"{name}: run make notebooks"
    assert nb.metadata.get("kernelspec", {}).get("name") == "python3"


def test_a_notebook_whose_code_changed_is_named_stale(tmp_path):
    refresh = _refresh_module()
    nb = _read("01_symbolic")
    assert refresh.problems(nb) == []
    cell = next(c for c in nb.cells if c.cell_type == "code")
    cell.source += "\nprint('changed')"
    assert refresh.problems(nb) == ["its code changed since its outputs were stored"]
    cell.execution_count = None
    assert "its cells were not all run, in order, in one session" in refresh.problems(nb)


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_documents_quick_mode(name):
    first = _read(name).cells[0]
    assert first.cell_type == "markdown"
    assert "CAKE_DRAKE_QUICK=1" in first.source


@pytest.mark.slow
@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_runs(name, tmp_path, monkeypatch):
    nb = _read(name)
    # After the notebook: Meshcat must have stayed off (it is opt-in, never started in CI).
    nb.cells.append(
        nbformat.v4.new_code_cell(
            "assert not globals().get('USE_MESHCAT', False), 'Meshcat is on by default'"
        )
    )
    monkeypatch.chdir(tmp_path)
    # A notebook keeps its plots in a temporary folder of its own, for a student to open
    # after; run here, that folder goes in the test's, not in the machine's /tmp.
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    before = sorted(NOTEBOOKS_DIR.iterdir())
    _refresh_module().execute(nb, tmp_path, quick=True)  # raises on any error, naming the cell

    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if o.output_type == "error"]  # fmt: skip
    assert not errors
    assert sorted(NOTEBOOKS_DIR.iterdir()) == before, "a notebook wrote files next to itself"


def test_graphviz_svg_names_missing_dot(tmp_path):
    missing = tmp_path / "no-such-dot"
    with pytest.raises(InputError, match="not found on PATH.*apt-get install graphviz"):
        graphviz_svg("digraph { a -> b }", dot=str(missing))


@needs_dot
def test_graphviz_svg_reports_bad_source():
    with pytest.raises(InputError, match="rejected the Graphviz source"):
        graphviz_svg("digraph { a -> ")


@needs_dot
def test_diagram_svg_names_systems_and_ports():
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import Adder, ConstantVectorSource

    builder = DiagramBuilder()
    source = builder.AddNamedSystem("source", ConstantVectorSource([1.0, 2.0]))
    adder = builder.AddNamedSystem("adder", Adder(2, 2))
    builder.Connect(source.get_output_port(), adder.get_input_port(0))
    builder.Connect(source.get_output_port(), adder.get_input_port(1))
    builder.ExportOutput(adder.get_output_port(), "sum")
    diagram = builder.Build()
    diagram.set_name("tiny")

    svg = diagram_svg(diagram)
    assert svg.lstrip().startswith("<?xml") and "</svg>" in svg
    for text in ("name=source", "name=adder", "sum"):
        assert text in svg

    assert ports_text(adder).splitlines() == [
        "adder (Adder)",
        "  input   u0   vector[2]",
        "  input   u1   vector[2]",
        "  output  sum  vector[2]",
    ]
