"""The static site: the notebooks executed in order and exported to HTML,
with an index page linking them. Images and animations are embedded in each
page and MathJax is copied beside the pages (from the ``jupyter-server-mathjax``
package), so the site opens from disk with no server and no network."""

from __future__ import annotations

import html
import importlib.util
import logging
import os
import shutil
from pathlib import Path
from unittest import mock

from .. import paths
from ..errors import SlamError
from ..viz.display import KERNEL_ENVIRONMENT

log = logging.getLogger(__name__)
NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"  # the checkout's: notebooks are not installed
TIMEOUT_S = 1800  # per notebook
TEMPLATE = Path(__file__).parent / "templates" / "offline.html.j2"
MATHJAX_DIR = "mathjax"  # the site's copy of MathJax 2.7, beside the pages
MATHJAX_URL = f"{MATHJAX_DIR}/MathJax.js?config=TeX-AMS-MML_HTMLorMML-full,Safe"  # the one full config it ships
MARKER = ".helpers-site"  # the file that marks a folder as a site this tool wrote (and may replace)


def notebook_paths() -> list[Path]:
    found = sorted(NOTEBOOKS.glob("[0-9][0-9]_*.ipynb"))
    if not found:
        raise SlamError(f"no notebooks found in {NOTEBOOKS}")
    return found


def build_site(out_dir: str | Path = "build/html", execute: bool = True) -> Path:
    """Execute (optionally) and export every notebook; returns index.html."""
    import nbformat
    from nbclient import NotebookClient
    from nbconvert import HTMLExporter

    exporter = HTMLExporter(
        template_name="lab",
        template_file=str(TEMPLATE),
        mathjax_url=MATHJAX_URL,
    )
    pages = []
    with paths.atomic_dir(out_dir, MARKER) as work:
        for path in notebook_paths():
            notebook = nbformat.read(path, as_version=4)
            if execute:
                log.info("executing %s", path.name)
                # Its kernel draws 3-D views as pictures: a page on disk has no kernel to talk to.
                with mock.patch.dict(os.environ, KERNEL_ENVIRONMENT):
                    where = {"metadata": {"path": str(NOTEBOOKS)}}
                    NotebookClient(notebook, timeout=TIMEOUT_S, resources=where).execute()
            body, _ = exporter.from_notebook_node(notebook)
            page = path.with_suffix(".html").name
            (work / page).write_text(body, encoding="utf-8")
            pages.append((page, _title(notebook, path)))
        (work / "index.html").write_text(_index(pages), encoding="utf-8")
        _copy_mathjax(work / MATHJAX_DIR)
        (work / MARKER).write_text("Written by python -m helpers site: the next build replaces this folder.\n")
    return Path(out_dir) / "index.html"


def _copy_mathjax(target: Path) -> None:
    """MathJax's scripts and web fonts, without its translations (2 of its 12 MB)."""
    spec = importlib.util.find_spec("jupyter_server_mathjax")  # found, not imported: it is a server extension
    if spec is None:
        raise SlamError("the site needs MathJax: pip install jupyter-server-mathjax (see environment.txt)")
    source = Path(spec.submodule_search_locations[0]) / "static"
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("localization"))


def _title(notebook, path: Path) -> str:
    for cell in notebook.cells:
        if cell.cell_type == "markdown":
            for line in cell.source.splitlines():
                if line.startswith("# "):
                    return line[2:].strip()
    return path.stem


def _index(pages) -> str:
    items = "\n".join(f'    <li><a href="{html.escape(page)}">{html.escape(title)}</a></li>' for page, title in pages)
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
  <meta charset="utf-8">
  <title>Aerial lidar SLAM, step by step</title>
  <style>
    body {{ font-family: system-ui, sans-serif; max-width: 44rem; margin: 3rem auto; line-height: 1.5; }}
    li {{ margin: 0.4rem 0; }}
  </style>
</head>
<body>
  <h1>Aerial lidar SLAM, step by step</h1>
  <p>A drone flies over an aerial map and scans it with a lidar. These pages rebuild the
  whole SLAM pipeline, one stage a page, from the simulated scans to the corrected map.</p>
  <ol>
{items}
  </ol>
</body>
</html>
"""
