"""How long a learner waits: every code cell of the tutorial, timed as it runs in a fresh kernel.

    .venv/bin/python benchmarks/bench_notebooks.py [--solutions] [--warm] [--top 10] [notebooks/04_submaps.ipynb ...]

The notebooks run in their order, each in its own kernel started as the
book's builder starts it (3-D views as pictures), with a cache folder of
their own that starts empty (``HELPERS_CACHE``): the first ``default_run()``
is computed where a learner meets it, and later notebooks read it, as on a
learner's first pass. ``--warm`` uses the usual cache instead (a second
pass). Nothing is written back to the notebooks.

Prints each notebook's total, then the slowest code cells (numbered from 0
among code cells, as nbval names them) with their first line, and the
cells over issue 22's 30 s. Timings are figures to read, never a test.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path
from unittest import mock

HERE = Path(__file__).resolve().parent
NOTEBOOKS = HERE.parent / "notebooks"
LIMIT_S = 30.0  # issue 22: no cell a learner runs takes longer on 2 cores


def cell_seconds(cell) -> float:
    """Seconds from the kernel starting a cell to its reply, from the timestamps nbclient records."""
    stamps = cell.metadata.get("execution", {})
    start, end = stamps.get("iopub.execute_input"), stamps.get("shell.execute_reply")
    if not (start and end):
        return float("nan")
    return (datetime.fromisoformat(end.rstrip("Z")) - datetime.fromisoformat(start.rstrip("Z"))).total_seconds()


def run(path: Path, environment: dict, sockets: Path) -> list[tuple[int, float, str]]:
    """(code cell number, seconds, first line) of every code cell of ``path``, executed as the book's builder
    executes it (:func:`helpers.site.build.execute_notebook`: a fresh kernel over Unix sockets named after
    ``sockets``) with ``environment`` added to the kernel's."""
    import nbformat

    from helpers.site.build import execute_notebook

    notebook = nbformat.read(path, as_version=4)
    with mock.patch.dict(os.environ, environment):
        execute_notebook(notebook, path, sockets)
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    return [(k, cell_seconds(cell), (cell.source.strip().splitlines() or [""])[0][:60]) for k, cell in enumerate(code)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("notebooks", nargs="*", type=Path, help="default: notebooks/0*.ipynb in order")
    parser.add_argument("--solutions", action="store_true", help="run each notebook's worked answers after it")
    parser.add_argument("--warm", action="store_true", help="use the usual cache (a second pass), not an empty one")
    parser.add_argument("--top", type=int, default=10, help="how many of the slowest cells to print")
    args = parser.parse_args()
    paths = args.notebooks or sorted(NOTEBOOKS.glob("0*.ipynb"))
    if args.solutions and not args.notebooks:
        paths = [p for path in paths for p in (path, NOTEBOOKS / "solutions" / f"{path.stem}_solutions.ipynb")]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        sys.exit(f"error: no such notebook: {', '.join(missing)}")

    with tempfile.TemporaryDirectory(prefix="bench-notebooks-") as scratch:
        environment = {}  # the kernel's own (3-D views as pictures) come from execute_notebook
        if not args.warm:
            environment["HELPERS_CACHE"] = str(Path(scratch) / "cache")
        print(f"{'notebook':40} {'cells':>5} {'total s':>8} {'slowest s':>9}")
        cells = []
        for path in paths:
            start = time.perf_counter()
            timed = run(path.resolve(), environment, Path(scratch) / "k")
            wall = time.perf_counter() - start
            slowest = max((s for _, s, _ in timed), default=float("nan"))
            print(f"{path.name:40} {len(timed):5d} {wall:8.1f} {slowest:9.1f}", flush=True)
            cells += [(seconds, path.name, k, first) for k, seconds, first in timed]
    cells.sort(reverse=True)
    print(f"\nslowest {args.top} code cells (numbered as nbval does):")
    for seconds, name, k, first in cells[: args.top]:
        print(f"{seconds:7.1f} s  {name} cell {k}: {first}")
    over = [c for c in cells if c[0] > LIMIT_S]
    print(f"\ncells over {LIMIT_S:.0f} s: {len(over)}" + "".join(f"\n  {n} cell {k}: {s:.1f} s" for s, n, k, _ in over))


if __name__ == "__main__":
    main()
