"""The tutorial as a book: the notebooks (executed, or as committed) built by
Sphinx with myst-nb and sphinx-book-theme, the tooling Jupyter Book is made
of. A landing page shows the result, says what each page teaches and offers
the project itself as a zip (``archive``), with the two commands that run it;
every page has the whole book in its sidebar, previous/next links and a
search box. MathJax 2.7 (from ``jupyter-server-mathjax``) is copied beside
the pages, and the theme's fonts and icons and the copy button of the code
cells and of the text's code blocks (sphinx-copybutton) are its own files, so
the book opens from disk with no server and no network. Cell tags
(``hide-input``, ``hide-cell``, ``remove-cell``) and admonitions
(```` ```{note} ```` or ``:::{tip}``) work; a cell JupyterLab shows folded is
folded in the book too (``cells``). A cell's ``mystnb: {figure: {caption,
name}, image: {alt}}`` metadata makes its picture a numbered figure with a
caption and alt text, the notebooks' own section numbers are checked and
"section 3.4" in the text links to it (``sphinx_ext``, ``sections``); the
landing page is written by ``landing``, the style by ``book.css``.

The Sphinx source tree (a generated ``conf.py`` and ``index.md``, copies of
the notebooks) lives in a temporary folder, so building leaves the checkout
as it was."""

from __future__ import annotations

import importlib.util
import io
import logging
import os
import re
import shutil
import warnings
from pathlib import Path
from unittest import mock

from helpers import outdir
from helpers.errors import SlamError
from helpers.site import archive, cells
from helpers.site.landing import RESULT_PICTURE, SOLUTIONS, TITLE, index_page
from helpers.viz.display import KERNEL_ENVIRONMENT

log = logging.getLogger(__name__)
NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"  # the checkout's: notebooks are not installed
FIGURES = "figures"  # notebooks/figures/: copied into the book
TIMEOUT_S = 1800  # per notebook
MATHJAX_DIR = "mathjax"  # the book's copy of MathJax 2.7, in its _static folder
MATHJAX_URL = f"{MATHJAX_DIR}/MathJax.js?config=TeX-AMS-MML_HTMLorMML-full,Safe"  # the one full config it ships
MARKER = ".helpers-site"  # lists what a build wrote: the next one may replace the folder while it holds only that

# Sphinx warnings that mean a broken book (a missing page, picture or link target) rather than a style nit.
FATAL_WARNINGS = re.compile(
    r"toctree contains reference to nonexisting document|image file not readable|undefined label|"
    r"unknown document|Could not find|not found|does not exist|\[myst\.xref_missing\]|\[myst\.iref_ambiguous\]|"
    r"Duplicate explicit target name|"  # two figures given one name: a link to it would reach either
    r"section number|is cited, but no heading has that number"  # helpers.site.sections: numbers, mentions
)

ANSI_COLOUR = re.compile(r"\x1b\[[0-9;]*m")

STYLE_SHEET = Path(__file__).with_name("book.css")  # the book's own style, copied into _static

# The generated conf.py: everything Sphinx is told.
CONF = {
    "project": TITLE,
    "author": "the aerial-lidar-slam authors",
    # The copy button's script and style sheet go to _static; ours numbers figures by chapter and gives every
    # picture a text alternative (helpers/site/sphinx_ext.py).
    "extensions": ["myst_nb", "sphinx_copybutton", "helpers.site.sphinx_ext"],
    "numfig": True,  # a cell's mystnb.figure caption is "Figure 3.2: ..." and {numref} can cite it
    "numfig_format": {"figure": "Figure %s", "table": "Table %s", "code-block": "Listing %s", "section": "Section %s"},
    "exclude_patterns": ["_build", "**.ipynb_checkpoints"],
    "myst_enable_extensions": ["dollarmath", "amsmath", "colon_fence"],  # $...$, $$...$$, ::: admonitions
    "nb_render_markdown_format": "gfm",  # Markdown outputs (chapter 2's parameter table): commonmark has no tables
    "myst_heading_anchors": 3,  # [text](#a-heading) links within a notebook
    "myst_update_mathjax": False,  # it writes a MathJax 3/4 configuration; ours is MathJax 2 (below)
    "nb_execution_mode": "off",  # build_site executes the notebooks itself, in the kernel environment
    "nb_merge_streams": True,
    # A copy button on the code cells and on the code blocks of the text (a command, a call to adapt), not on
    # what the cells print (an output's box is a div.output.highlight-*).
    "copybutton_selector": "div[class*=highlight-]:not(.output) > div.highlight > pre",
    "nb_ipywidgets_js": {},  # no widget in our outputs; its default loads require.js from a CDN
    "mathjax_path": MATHJAX_URL,  # under _static
    "mathjax2_config": {
        "tex2jax": {
            "inlineMath": [["\\(", "\\)"]],
            "displayMath": [["\\[", "\\]"]],
            "processEscapes": True,
            "processClass": "math|output_area",
            "ignoreClass": "tex2jax_ignore|mathjax_ignore|document",
        },
        # The copy has only the STIX web fonts (jupyter-server-mathjax's): MathJax's default TeX ones are absent.
        "HTML-CSS": {"availableFonts": [], "preferredFont": None, "webFont": "STIX-Web", "imageFont": None},
        "showMathMenu": False,
        "messageStyle": "none",
        "fast-preview": {"disabled": True},  # its quick first pass would ask for the TeX fonts too
        # The hidden MathML kept for screen readers asks for TeX fonts by mathvariant (script, double-struck):
        # it keeps the fonts around it instead.
        "styles": {".MJX_Assistive_MathML [mathvariant]": {"font-family": "inherit"}},
    },
    "html_theme": "sphinx_book_theme",
    "html_title": TITLE,
    "html_static_path": ["_static"],  # the book's style sheet, STYLE_SHEET
    "html_css_files": [STYLE_SHEET.name],
    "html_show_sphinx": False,
    # Sphinx's search shows an excerpt of each page it finds by fetching the page, which a browser refuses
    # for a page opened from disk (file://): the results would be bare titles and the console full of errors.
    # The page titles alone, then, from disk and served over http (python -m http.server -d build/html) alike.
    "html_show_search_summary": False,
    "html_theme_options": {
        "home_page_in_toc": True,
        "show_navbar_depth": 1,
        "show_toc_level": 2,
        "use_download_button": True,  # the page's notebook, from _sources
        "use_fullscreen_button": False,
        "use_repository_button": False,
        "use_issues_button": False,
        "use_edit_page_button": False,
        "launch_buttons": {},
        "navigation_with_keys": True,
        "navbar_persistent": [],  # the sidebar has the search box; this one would sit alone in a top bar
    },
}


def notebook_paths() -> list[Path]:
    """The tutorial's notebooks, in order."""
    found = sorted(NOTEBOOKS.glob("[0-9][0-9]_*.ipynb"))
    if not found:
        raise SlamError(f"no notebooks found in {NOTEBOOKS}")
    return found


def solution_paths() -> list[Path]:
    """The worked answers to the exercises (possibly none), in order."""
    return sorted((NOTEBOOKS / SOLUTIONS).glob("*.ipynb"))


def build_site(out_dir: str | Path = "build/html", execute: bool = True) -> Path:
    """Execute (optionally) the notebooks and build the book; returns its index.html."""
    chapters, solutions = notebook_paths(), solution_paths()
    with outdir.atomic_dir(out_dir, MARKER) as work, outdir.scratch_dir("helpers-book") as tmp:
        source = tmp / "source"
        source.mkdir()
        (source / SOLUTIONS).mkdir()
        sockets = tmp / "k"  # the kernels' IPC sockets k-1 ... k-5 (a Unix socket's path has at most 107 bytes)
        for path in chapters:
            _add_notebook(path, source / path.name, execute, sockets)
        for path in solutions:
            _add_notebook(path, source / SOLUTIONS / path.name, execute, sockets)
        if (NOTEBOOKS / FIGURES).is_dir():  # pictures the notebooks' text may show, and the landing page's
            shutil.copytree(NOTEBOOKS / FIGURES, source / FIGURES, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
        picture = (source / RESULT_PICTURE).is_file()
        # The project to download (the notebooks as in the checkout, the package, the Makefile, ...): the
        # landing page links it and says its size.
        project = archive.write_archive(NOTEBOOKS.parent, tmp / archive.ARCHIVE, skip=(work, Path(out_dir)))
        landing = index_page(source, chapters, solutions, picture, archive.ARCHIVE, project.stat().st_size)
        (source / "index.md").write_text(landing, encoding="utf-8")
        (source / "conf.py").write_text(_conf(), encoding="utf-8")
        (source / "_static").mkdir()
        shutil.copyfile(STYLE_SHEET, source / "_static" / STYLE_SHEET.name)
        # myst-nb writes beside Sphinx's output folder (jupyter_execute/): so it builds in tmp, then moves.
        built = _sphinx(source, tmp / "build" / "html", tmp / "build" / "doctrees")
        shutil.copytree(built, work, dirs_exist_ok=True)
        _copy_mathjax(work / "_static" / MATHJAX_DIR)
        shutil.move(project, work / archive.ARCHIVE)
    return Path(out_dir) / "index.html"


def _add_notebook(path: Path, target: Path, execute: bool, sockets: Path) -> None:
    import nbformat

    notebook = nbformat.read(path, as_version=4)
    if execute:
        execute_notebook(notebook, path, sockets)
    cells.prepare(notebook)  # folded cells stay folded, a figure cell's other outputs stay out of its figure
    nbformat.write(notebook, target)


def execute_notebook(notebook, path: Path, sockets: Path) -> None:
    """Run every cell of ``notebook`` (read from ``path``, which it runs beside) in a fresh kernel, as the
    book's notebooks are run; ``benchmarks/bench_notebooks.py`` times them so."""
    from nbclient import NotebookClient
    from traitlets.config import Config

    log.info("executing %s", path.name)
    # The kernel talks to us over Unix sockets (files named after ``sockets``), not TCP on localhost: no port
    # another user of the machine could reach, and no warning from the kernel that TCP is unencrypted.
    ipc = Config({"KernelManager": {"transport": "ipc", "ip": str(sockets)}})
    # Its kernel draws 3-D views as pictures: a page on disk has no kernel to talk to.
    with mock.patch.dict(os.environ, KERNEL_ENVIRONMENT):
        where = {"metadata": {"path": str(path.parent)}}
        NotebookClient(notebook, timeout=TIMEOUT_S, resources=where, config=ipc, log=KERNEL_LOG).execute()


class _DashComm(logging.Filter):
    """Drops nbclient's "No handler found for comm target 'dash'": importing Open3D imports Dash, which
    opens a channel to a Jupyter front end that a book being built does not have, and needs none of."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "No handler found for comm target 'dash'" not in record.getMessage()


KERNEL_LOG = logging.getLogger(f"{__name__}.kernel")  # what nbclient says while it executes a notebook
KERNEL_LOG.addFilter(_DashComm())


def _conf() -> str:
    lines = ['"""Generated by helpers.site.build: the book\'s Sphinx configuration."""', ""]
    lines += [f"{key} = {value!r}" for key, value in CONF.items()]
    return "\n".join(lines) + "\n"


def _sphinx(source: Path, out: Path, doctrees: Path) -> Path:
    """Sphinx's HTML build into ``out``; fails on a warning that means a broken page, logs the others."""
    from sphinx.application import Sphinx
    from sphinx.util.docutils import docutils_namespace, patch_docutils

    status, messages = io.StringIO(), io.StringIO()
    with patch_docutils(source), docutils_namespace(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # the theme's and myst's use of Sphinx, not ours to mend
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        app = Sphinx(source, source, out, doctrees, "html", status=status, warning=messages, freshenv=True)
        app.build(force_all=True)
    text = ANSI_COLOUR.sub("", messages.getvalue()).replace(f"{source}{os.sep}", "")
    reported = [line for line in text.splitlines() if line.strip()]
    for line in reported:
        log.warning("sphinx: %s", line)
    fatal = [line for line in reported if FATAL_WARNINGS.search(line)]
    if app.statuscode or fatal:
        raise SlamError("the book has broken parts:\n" + "\n".join(fatal or reported))
    return out


def _copy_mathjax(target: Path) -> None:
    """MathJax's scripts and web fonts, without its translations (2 of its 12 MB)."""
    spec = importlib.util.find_spec("jupyter_server_mathjax")  # found, not imported: it is a server extension
    if spec is None:
        raise SlamError("the site needs MathJax: pip install jupyter-server-mathjax (see environment.txt)")
    source = Path(spec.submodule_search_locations[0]) / "static"
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("localization"))
