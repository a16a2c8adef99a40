"""Run every notebook and store it with its outputs, so a repository page shows them.

    python notebooks/refresh.py [NAME ...]     (make notebooks)
    python notebooks/refresh.py --check        (exit 1 naming a notebook that is stale)

Each notebook runs in full (not in the tests' quick mode) in a fresh temporary folder,
with matplotlib's inline backend and a fixed hash seed, and is written back with its
outputs. Its metadata then records a fingerprint of its code cells
(``cake_drake.code_sha256``): ``--check`` fails for a notebook whose code changed since
it was last run, or that has a cell without outputs run in order, or an error among its
outputs. The tests run
``--check`` and, separately, execute every notebook in quick mode.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import tempfile
from pathlib import Path

import nbformat

HERE = Path(__file__).resolve().parent
CELL_TIMEOUT_S = 900


def code_sha256(nb) -> str:
    """The fingerprint of a notebook's code: its code cells' sources, in order."""
    digest = hashlib.sha256()
    for cell in nb.cells:
        if cell.cell_type == "code":
            digest.update(cell.source.encode())
            digest.update(b"\0")
    return digest.hexdigest()


def problems(nb) -> list[str]:
    """Why a notebook's stored outputs are not those of its current code (empty: fine)."""
    found = []
    stamp = nb.metadata.get("cake_drake", {}).get("code_sha256")
    if stamp != code_sha256(nb):
        found.append("its code changed since its outputs were stored")
    counts = [c.execution_count for c in nb.cells if c.cell_type == "code"]
    if counts != list(range(1, len(counts) + 1)):
        found.append("its cells were not all run, in order, in one session")
    if any(o.output_type == "error" for c in nb.cells if c.cell_type == "code" for o in c.outputs):
        found.append("an error is among its outputs")
    return found


def execute(nb, work: str | Path, quick: bool = False) -> None:
    """Run ``nb`` in place in the folder ``work``: a fixed hash seed, the kernel this
    interpreter; with ``quick`` (the tests' mode) ``CAKE_DRAKE_QUICK=1`` and matplotlib's
    Agg backend (nothing to show), else the inline backend (pyplot figures are stored).
    Raises nbclient's CellExecutionError, naming the cell, on any error."""
    from nbclient import NotebookClient

    backend = "Agg" if quick else "module://matplotlib_inline.backend_inline"
    env = {"MPLBACKEND": backend, "PYTHONHASHSEED": "0"}
    saved = {k: os.environ.get(k) for k in (*env, "CAKE_DRAKE_QUICK", "PATH")}
    os.environ.update(env)
    if quick:
        os.environ["CAKE_DRAKE_QUICK"] = "1"
    else:
        os.environ.pop("CAKE_DRAKE_QUICK", None)
    # The kernel is this interpreter (jupyter_client starts "python" from PATH).
    os.environ["PATH"] = str(Path(sys.executable).parent) + os.pathsep + os.environ["PATH"]
    try:
        NotebookClient(
            nb,
            kernel_name="python3",
            timeout=CELL_TIMEOUT_S,
            resources={"metadata": {"path": str(work)}},
        ).execute()
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def refresh(path: Path) -> None:
    nb = nbformat.read(path, as_version=4)
    with tempfile.TemporaryDirectory() as work:
        execute(nb, work)
    for cell in nb.cells:  # nothing that changes from one refresh to the next but outputs
        cell.metadata.pop("execution", None)
    nb.metadata.setdefault("cake_drake", {})["code_sha256"] = code_sha256(nb)
    tmp = path.with_name(path.name + ".part")
    nbformat.write(nb, tmp)
    tmp.replace(path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("names", nargs="*", help="notebooks to run (default: all)")
    p.add_argument("--check", action="store_true", help="only check they are current")
    args = p.parse_args(argv)
    paths = sorted(HERE.glob("*.ipynb"))
    if args.names:
        wanted = {n.removesuffix(".ipynb") for n in args.names}
        unknown = wanted - {p.stem for p in paths}
        if unknown:
            known = ", ".join(p.stem for p in paths)
            print(f"error: no notebook {sorted(unknown)[0]}; choose from: {known}", file=sys.stderr)
            return 2
        paths = [p for p in paths if p.stem in wanted]
    if args.check:
        stale = [(p, problems(nbformat.read(p, as_version=4))) for p in paths]
        stale = [(p, why) for p, why in stale if why]
        for p, why in stale:
            print(f"notebooks/{p.name}: {'; '.join(why)}: run make notebooks", file=sys.stderr)
        if not stale:
            print(f"{len(paths)} notebooks stored with the outputs of their current code")
        return 1 if stale else 0
    for path in paths:
        print(f"running notebooks/{path.name}", file=sys.stderr, flush=True)
        refresh(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
