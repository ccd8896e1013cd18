"""The book's conventions for the notebooks, on a small book made for them
(built without executing): a figure cell's ``mystnb`` metadata makes a
numbered figure with its caption under the picture and its alt text; a
picture without alt text gets the page's title and its number; an exercise's
``<details>`` hint shows folded, its Markdown rendered; a cell JupyterLab
shows folded is folded in the book; relative links between notebooks and to
the worked answers become links between pages. Then Chromium opens the hint
and the folded cells from disk."""

import base64
import io
import re
from contextlib import redirect_stderr
from pathlib import Path

import nbformat.v4
import numpy as np
import pytest
from PIL import Image
from test_site import MATHJAX_DONE, _local, _parse, _pictures

from helpers.__main__ import main
from helpers.site import build as site_module

HINT = "<details><summary>Hint</summary>\n\nLook at the **median** of `errors`, and at $x^2$.\n\n</details>"
TABLE = "| scan | error (m) |\n|---|---|\n| 1 | 0.25 |"
FIRST = {"caption": "The first picture, **in bold**: what to look at.", "name": "fig-03-first"}
FOLDED_SOURCE = "# Check: folded\nprint('PRINTED BY A FOLDED CHECK'.lower())"  # its output is not in its source
FOLDED_OUTPUT = "printed by a folded check"


def _png(seed: int) -> str:
    pixels = np.random.default_rng(seed).integers(0, 255, (30, 40, 3), dtype=np.uint8)
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")
    return base64.b64encode(buffer.getvalue()).decode()


def _figure_cell(seed: int, width: int | None = None, **mystnb) -> nbformat.NotebookNode:
    """A cell showing a picture; ``width``: shown at that width, as ``show_figure`` shows its pictures."""
    cell = nbformat.v4.new_code_cell(f"draw({seed})", metadata={"mystnb": mystnb} if mystnb else {})
    data = {"image/png": _png(seed), "text/plain": "<Figure>"}
    shown = {"image/png": {"width": width}} if width else {}
    cell.outputs = [nbformat.v4.new_output("display_data", data=data, metadata=shown)]
    return cell


def _printing_cell(source: str, printed: str, **jupyter) -> nbformat.NotebookNode:
    cell = nbformat.v4.new_code_cell(source, metadata={"jupyter": jupyter})
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=printed + "\n")]
    return cell


@pytest.fixture()
def small_book(tmp_path, monkeypatch) -> Path:
    """Three pages (a chapter 1, a chapter 3 with figures, an exercise and folded cells, its worked answers)."""
    folder = tmp_path / "notebooks"
    (folder / "solutions").mkdir(parents=True)
    first = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# 1. First\n\nSome text.")])
    nbformat.write(first, folder / "01_first.ipynb")
    cells = [
        nbformat.v4.new_markdown_cell(
            "# 3. Figures\n\nAfter [notebook 1](01_first.ipynb); "
            "the [worked answers](solutions/03_figures_solutions.ipynb) are in the appendix."
        ),
        _figure_cell(1, width=20, figure=FIRST, image={"alt": "a square of coloured noise"}),
        _figure_cell(2, figure={"caption": "A second picture.", "name": "fig-03-second"}),
        _figure_cell(3),
        _figure_cell(4, figure={"caption": "A table, a picture, a value.", "name": "fig-03-table"}),
        nbformat.v4.new_markdown_cell(f"## Exercises\n\n### Exercise 3.1: a median\n\nFind it.\n\n{HINT}\n\nNext."),
        _printing_cell(FOLDED_SOURCE, FOLDED_OUTPUT, source_hidden=True, outputs_hidden=True),
        _printing_cell("print('shown' + ' output')", "shown output", source_hidden=True),
    ]
    table = nbformat.v4.new_output("display_data", data={"text/markdown": TABLE, "text/plain": "a table"})
    cells[4].outputs = [table, *cells[4].outputs, nbformat.v4.new_output("execute_result", data={"text/plain": "42"})]
    notebook = nbformat.v4.new_notebook(cells=cells, metadata={"language_info": {"name": "python"}})
    nbformat.write(notebook, folder / "03_figures.ipynb")
    answers = nbformat.v4.new_markdown_cell("# 3. Worked answers\n\nBack to [notebook 3](../03_figures.ipynb).")
    nbformat.write(nbformat.v4.new_notebook(cells=[answers]), folder / "solutions" / "03_figures_solutions.ipynb")
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)
    out = tmp_path / "html"
    with redirect_stderr(io.StringIO()) as err:
        assert main(["site", "--out", str(out), "--no-execute"]) == 0, err.getvalue()
    assert "tags" not in nbformat.read(folder / "03_figures.ipynb", 4).cells[6].metadata  # only the book's copy
    return out


def test_figure_cells_become_numbered_figures_with_their_captions_and_alt_text(small_book):
    page = small_book / "03_figures.html"
    found = [(p["alt"], p["figure"] and p["figure"]["id"], p["figure"] and p["figure"]["number"])
             for p in _pictures(page)]  # fmt: skip
    assert found == [
        ("a square of coloured noise", "fig-03-first", "Figure 3.1"),
        ("3. Figures, figure 3.2", "fig-03-second", "Figure 3.2"),  # no alt given: the title and its number
        ("3. Figures, picture 3", None, None),  # no figure metadata: no caption, its place on the page
        ("3. Figures, figure 3.3", "fig-03-table", "Figure 3.3"),
    ]
    html = page.read_text(encoding="utf-8")
    figures = re.findall(r"<figure.*?</figure>", html, re.DOTALL)
    assert len(figures) == 3 and "<table" not in figures[2] and "42" not in figures[2], "a figure holds more"
    table, figure = html.index("<td><p>0.25</p></td>"), html.index(figures[2])
    assert table < figure and "42" in html[figure + len(figures[2]) :], "the cell's other outputs lost or moved"
    assert "the rest of the cell above" not in html
    figure = re.search(r'<figure[^>]*id="fig-03-first".*?</figure>', html, re.DOTALL).group(0)
    assert figure.index("<img") < figure.index("<figcaption"), "the caption is not under the picture"
    assert "<strong>in bold</strong>: what to look at." in figure, "the caption's Markdown is not rendered"


def test_two_figures_of_one_name_fail_the_build(tmp_path, monkeypatch):
    """A link to the name would reach either: the build stops and names the notebook and the name."""
    folder = tmp_path / "notebooks"
    folder.mkdir()
    twice = {"caption": "A picture.", "name": "fig-01-same"}
    cells = [nbformat.v4.new_markdown_cell("# 1. Twice"), _figure_cell(1, figure=twice), _figure_cell(2, figure=twice)]
    nbformat.write(nbformat.v4.new_notebook(cells=cells), folder / "01_twice.ipynb")
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)
    with redirect_stderr(io.StringIO()) as err:
        code = main(["site", "--out", str(tmp_path / "html"), "--no-execute"])
    said = err.getvalue()
    assert code == 2 and 'Duplicate explicit target name: "fig-01-same"' in said and "01_twice" in said, said
    assert not (tmp_path / "html").exists()


def test_each_picture_links_to_its_own_file_to_be_opened_alone(small_book):
    """A phone's reader taps a figure to open it whole and zoom: each output picture is a link to its file."""
    page = small_book / "03_figures.html"
    html = page.read_text(encoding="utf-8")
    linked = re.findall(r'<a class="[^"]*image-reference[^"]*" href="([^"]+)"><img [^>]*src="([^"]+)"', html)
    assert len(linked) == len(_pictures(page)) == 4, f"{len(linked)} linked pictures"
    assert all(href == src and (page.parent / href).is_file() for href, src in linked), linked
    assert re.search(r'<img alt="a square of coloured noise"[^>]*width="20"', html), "not shown at its width"


def test_relative_links_between_notebooks_become_links_between_pages(small_book):
    chapter, answers = small_book / "03_figures.html", small_book / "solutions" / "03_figures_solutions.html"
    links = _parse(chapter).main
    assert "01_first.html" in links and "solutions/03_figures_solutions.html" in links, links
    assert "../03_figures.html#exercises" in _parse(answers).main  # back to the chapter's exercises
    for page in (chapter, answers):
        for href in _parse(page).main:
            target = _local(page, href)
            assert target is None or target.is_file(), f"{page.name} links {href}, which the book lacks"


def test_a_hint_is_folded_with_its_markdown_rendered(small_book):
    html = (small_book / "03_figures.html").read_text(encoding="utf-8")
    hint = re.search(r"<details><summary>Hint</summary>(.*?)</details>", html, re.DOTALL)
    assert hint, "the hint is not a <details> with its summary"
    inside = hint.group(1)
    assert "<strong>median</strong>" in inside and "<code" in inside and 'class="math' in inside, inside
    assert "**" not in inside and "`" not in inside, f"raw Markdown in the hint: {inside}"


def test_cells_jupyterlab_shows_folded_are_folded_in_the_book(small_book):
    html = (small_book / "03_figures.html").read_text(encoding="utf-8")
    folded = re.findall(r'<details class="[^"]*\bhide\b.*?</details>', html, re.DOTALL)
    assert len(folded) == 2, f"{len(folded)} folded parts"
    assert "# Check: folded" in folded[0] and FOLDED_OUTPUT in folded[0], "the folded check's cell is not folded"
    assert "shown" in folded[1] and "shown output" not in folded[1] and "shown output" in html, "input only"


def test_the_hint_and_the_folded_cells_open_in_the_browser(small_book, browser):
    browser.resize(400, 800)
    browser.open((small_book / "03_figures.html").resolve().as_uri())
    browser.evaluate(MATHJAX_DONE)
    visible = """[document.querySelector('article details:not(.hide) p'),
      ...[...document.querySelectorAll('div.cell')].slice(-2).flatMap(cell =>
        [cell.querySelector('.cell_input'), cell.querySelector('.cell_output')])].map(e => e.checkVisibility())"""
    assert browser.evaluate(visible) == [False, False, False, False, True], "folded at first"
    for summary in ("article details:not(.hide) > summary", "details.hide > summary"):
        x, y = browser.evaluate(f"""(() => {{
          const first = document.querySelector({summary!r});
          first.scrollIntoView({{block: 'center'}});
          const r = first.getBoundingClientRect();
          return [r.left + 10, r.top + r.height / 2];
        }})()""")
        browser.click(x, y)  # as a reader's click: the hint, then the folded check
    browser.evaluate("document.querySelectorAll('details.hide')[1].open = true")  # the input-only fold
    assert browser.evaluate(visible) == [True, True, True, True, True], "open after a click"
    typeset = "document.querySelectorAll('article details:not(.hide) .MathJax').length"
    assert browser.evaluate(typeset) == 1, "the hint's formula is not typeset"
    leaving = [url for url in browser.requested() if not url.startswith(("file:", "data:", "about:"))]
    assert not leaving, f"the page asked the network for {leaving}"
