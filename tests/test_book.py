"""What the book offers a reader, checked without a browser (issue 62, items 12 to 16):

- the project to download: a zip of what the README's two commands and the
  notebooks need, and nothing built, cached or installed;
- the notebooks' section numbers, checked by the build (no heading numbered
  twice), and "section 3.4" in the text a link to that section's anchor;
- the landing page: its two commands, SLAM spelled out, no title repeated;
- maths in MathJax 2 set on the line and scrolling when wide (the style rule);
- a copy button on the text's code blocks too; search excerpts off from disk;
- no text of a picture under 11 px where the book shows it: the figures' type
  and width, measured on figures drawn as the notebooks draw them, the 3-D
  views' text and the animations' frames.
"""

import ast
import base64
import html as html_module
import io
import re
import zipfile
from contextlib import redirect_stderr
from pathlib import Path
from types import SimpleNamespace

import matplotlib
import nbformat.v4
import numpy as np
import pytest
from PIL import Image

from helpers.__main__ import main
from helpers.site import archive, landing, sections
from helpers.site import build as site_module
from helpers.viz import (
    graph_figures,
    ground_figures,
    parameter_figures,
    registration_figures,
    render,
    style,
    sweep_figures,
)
from helpers.viz.live import LiveView
from helpers.viz.player import FRAME_DPI, scan_player

ROOT = Path(__file__).resolve().parents[1]
VIZ = ROOT / "helpers" / "viz"
BOOK_CSS = ROOT / "helpers" / "site" / "book.css"


def _site(out: Path) -> tuple[int, str]:
    with redirect_stderr(io.StringIO()) as err:
        code = main(["site", "--out", str(out), "--no-execute"])
    return code, err.getvalue()


def _book(tmp_path, monkeypatch, pages: dict[str, list[str]]) -> tuple[int, str, Path]:
    """A book of the given notebooks (file name: its Markdown cells) built without running them."""
    folder = tmp_path / "notebooks"
    (folder / "solutions").mkdir(parents=True)
    for name, cells in pages.items():
        notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(text) for text in cells])
        nbformat.write(notebook, folder / name)
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)
    out = tmp_path / "html"
    code, err = _site(out)
    return code, err, out


# 12. The project to download


def test_the_archive_holds_the_project_and_nothing_built_cached_or_installed(tmp_path):
    """On a copy of a project's top folder with everything a working checkout gathers around it."""
    project = tmp_path / "project"
    for name in ("README.md", "LICENSE", "Makefile", "environment.txt", "pyproject.toml", "CHANGELOG.md"):
        (project / name).parent.mkdir(parents=True, exist_ok=True)
        (project / name).write_text(f"{name}\n")
    kept = [
        "helpers/__init__.py",
        "helpers/slam/pipeline.py",
        "notebooks/01_dataset.ipynb",
        "notebooks/conftest.py",
        "notebooks/figures/result.png",
        "notebooks/solutions/01_dataset_solutions.ipynb",
        "data/aerialMap.tar.gz",
        "docs/REFERENCE.md",
        "benchmarks/README.md",
        "tests/test_book.py",
        "jupyter/labconfig/page_config.json",
    ]
    dropped = [
        "build/html/index.html",
        "build/run/metrics.json",
        ".venv/bin/python",
        ".git/HEAD",
        "data/cache/maps/tile.npz",
        "helpers/__pycache__/x.cpython-311.pyc",
        "notebooks/.ipynb_checkpoints/01_dataset-checkpoint.ipynb",
        "aerial_lidar_slam_helpers.egg-info/PKG-INFO",
        ".pytest_cache/README.md",
        "tests/.ruff_cache/x",
        "scratch.txt",  # a file of the top folder the archive does not name
    ]
    for name in kept + dropped:
        (project / name).parent.mkdir(parents=True, exist_ok=True)
        (project / name).write_text(name)
    (project / "Makefile").write_bytes(b"run:\n\t$(PY) -m helpers run\n")  # a recipe's tab
    zipped = archive.write_archive(project, tmp_path / archive.ARCHIVE)
    with zipfile.ZipFile(zipped) as opened:
        names = opened.namelist()
        assert opened.read(f"{archive.NAME}/Makefile") == b"run:\n\t$(PY) -m helpers run\n"
    assert all(name.startswith(f"{archive.NAME}/") for name in names), "not all under one folder"
    inside = {name.removeprefix(f"{archive.NAME}/") for name in names}
    top = {"README.md", "LICENSE", "Makefile", "environment.txt", "pyproject.toml", "CHANGELOG.md"}
    assert inside == top | set(kept), f"missing {top | set(kept) - inside}, extra {inside - top - set(kept)}"


def test_the_checkouts_archive_holds_what_the_readme_and_the_notebooks_need():
    """The file list of this checkout's archive (not zipped: the book's tests zip it)."""
    files = {path.as_posix() for path in archive.archived_files(ROOT)}
    for needed in ("README.md", "LICENSE", "Makefile", "environment.txt", "pyproject.toml", "helpers/__init__.py",
                   "notebooks/figures/result.png", "data/aerialMap.tar.gz", "data/gTruthWayPoints.mat",
                   "docs/REFERENCE.md", "benchmarks/README.md", "jupyter/jupyter_server_config.py",
                   "tests/nbval_sanitize.cfg"):  # fmt: skip
        assert needed in files, f"the archive lacks {needed}"
    notebooks = {p.relative_to(ROOT).as_posix() for p in (ROOT / "notebooks").rglob("*.ipynb")}
    notebooks = {name for name in notebooks if ".ipynb_checkpoints" not in name}
    assert notebooks <= files and any(name.startswith("notebooks/solutions/") for name in notebooks)
    for name in files:
        parts = name.split("/")
        assert parts[0] not in ("build", ".venv", ".git"), name
        assert not any(part.startswith(".") or part == "__pycache__" for part in parts), name
        assert not name.startswith("data/cache/") and not name.endswith(".pyc"), name


def test_the_book_offers_the_archive_and_the_readmes_two_commands(tmp_path, monkeypatch):
    code, err, out = _book(tmp_path, monkeypatch, {"01_page.ipynb": ["# 1. A page\n\nSome text."]})
    assert code == 0, err
    zipped = out / archive.ARCHIVE
    with zipfile.ZipFile(zipped) as opened:
        assert f"{archive.NAME}/notebooks/01_page.ipynb" in opened.namelist()
    assert archive.ARCHIVE in (out / site_module.MARKER).read_text(), "a rebuild could not replace it"
    html = (out / "index.html").read_text(encoding="utf-8")
    assert f'<a href="{archive.ARCHIVE}" download>' in html, "the landing page does not link the archive"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    commands = re.search(r"## Two commands.*?```bash\n(.*?)```", readme, re.DOTALL).group(1)
    blocks = [html_module.unescape(re.sub(r"<[^>]+>", "", b)) for b in re.findall(r"<pre>(.*?)</pre>", html, re.S)]
    given = [line.split("#")[0].strip() for block in blocks for line in block.splitlines()]
    assert re.findall(r"^(make \w+)", commands, re.MULTILINE) == [line for line in given if line], given
    words = " ".join(re.sub(r"<[^>]+>", " ", html).split())
    assert "make lab" in words and "helpers/slam/pipeline.py" in words, "how to open the notebooks, what a file is"


# 16. Navigation: section numbers, their links and anchors


CHAPTER_3 = [
    "# 3. Registration\n\nAs section 3.2 shows, and sections 3.1 and 3.1.1; exercise 3.1 asks.",
    "## 3.1 The pair\n\nText.",
    "### 3.1.1 A detail\n\nSee `section 3.2` in code, not a link; a section 0.5 m wide is no section.",
    "## 3.2 Downsampling\n\nBack to section 3.1.",
    "## Exercises\n\n### Exercise 3.1: a median\n\nFind it.",
]
CHAPTER_4 = [
    "# 4. Submaps\n\nAs in section 3.2 of [notebook 3](03_registration.ipynb), and [notebook 3](03_registration.ipynb)."
]


def _hrefs(page: Path, text: str) -> list[str]:
    """Where each link of ``page`` whose text is ``text`` goes."""
    links = re.findall(r'<a [^>]*href="([^"]*)"[^>]*>(.*?)</a>', page.read_text(encoding="utf-8"), re.DOTALL)
    return [href for href, inside in links if re.sub(r"<[^>]+>", "", inside) == text]


def test_section_mentions_link_to_their_sections_on_any_page(tmp_path, monkeypatch):
    answers = "# 3. Worked answers\n\nThe exercises of [notebook 3](../03_registration.ipynb); section 3.1.1 helps."
    code, err, out = _book(tmp_path, monkeypatch, {"03_registration.ipynb": CHAPTER_3, "04_submaps.ipynb": CHAPTER_4,
                                                   "solutions/03_registration_solutions.ipynb": [answers]})  # fmt: skip
    assert code == 0, err
    three, four = out / "03_registration.html", out / "04_submaps.html"
    assert _hrefs(three, "section 3.2") == ["#section-3-2"]
    assert _hrefs(three, "sections 3.1") == ["#section-3-1"] and _hrefs(three, "3.1.1") == ["#section-3-1-1"]
    assert _hrefs(three, "exercise 3.1") == ["#exercise-3-1"] and _hrefs(three, "section 3.1") == ["#section-3-1"]
    page = three.read_text(encoding="utf-8")
    assert "<code" in page and 'href="#section-3-2"><code' not in page, "a mention in code became a link"
    assert "section 0.5 m" in page.replace("\n", " ")
    # Across pages: the mention and the notebook link after it both land on the section; a bare link stays.
    assert _hrefs(four, "section 3.2") == ["03_registration.html#section-3-2"]
    assert _hrefs(four, "notebook 3") == ["03_registration.html#section-3-2", "03_registration.html"]
    solutions = out / "solutions" / "03_registration_solutions.html"
    assert _hrefs(solutions, "notebook 3") == ["../03_registration.html#exercises"], "back to the exercises"
    assert _hrefs(solutions, "section 3.1.1") == ["../03_registration.html#section-3-1-1"]
    for page, hrefs in ((three, _hrefs(three, "section 3.2")), (four, _hrefs(four, "section 3.2"))):
        for href in hrefs:
            target, _, anchor = href.partition("#")
            html = (page.parent / target if target else page).read_text(encoding="utf-8")
            assert f'id="{anchor}"' in html, f"{href} from {page.name}: no such anchor"


def test_a_section_number_given_twice_stops_the_build_with_the_number_it_should_have(tmp_path, monkeypatch):
    """Chapter 3 once had two headings "3.4.1": the build says which number the second one should have."""
    twice = [*CHAPTER_3[:3], "### 3.1.1 Another detail\n\nText.", *CHAPTER_3[3:]]
    code, err, out = _book(tmp_path, monkeypatch, {"03_registration.ipynb": twice})
    assert code == 2 and not out.exists(), err
    assert 'section number 3.1.1 of "3.1.1 Another detail" should be 3.1.2' in err, err
    assert "already" in err and "03_registration" in err, err


@pytest.mark.parametrize(
    ("cells", "said"),
    [
        (["# 3. R", "## 3.1 A", "## 3.3 C"], 'section number 3.3 of "3.3 C" should be 3.2'),
        (["# 3. R", "## 3.1 A", "### 3.2.1 B"], 'section number 3.2.1 of "3.2.1 B" should be 3.1.1'),
        (["# 2. R", "## 2.1 A"], 'section number 2 of "2. R" should be 3'),
        (["# 3. R\n\nAs section 3.9 says.", "## 3.1 A"], "section 3.9 is cited, but no heading has that number"),
    ],
)
def test_a_number_out_of_order_or_cited_but_missing_stops_the_build(tmp_path, monkeypatch, cells, said):
    code, err, _ = _book(tmp_path, monkeypatch, {"03_r.ipynb": cells})
    assert code == 2 and said in err, err


def test_the_checks_number_each_level_under_its_own_parent():
    headings = [("section", "3", 1, "3. R", ""), ("section", "3.1", 2, "3.1 A", ""),
                ("section", "3.1.1", 3, "3.1.1 a", ""), ("section", "3.2", 2, "3.2 B", ""),
                ("section", "3.2.1", 3, "3.2.1 b", ""), ("plain", "", 2, "Exercises", ""),
                ("exercise", "3.1", 3, "Exercise 3.1", "")]  # fmt: skip
    assert sections.number_problems("3", headings) == []
    assert sections.number_problems("3", [*headings, ("section", "3.2.2", 3, "3.2.2 c", "")]) == [
        'section number 3.2.2 of "3.2.2 c": the heading above it has no number'
    ]


# 16. The landing page


def test_the_landing_pages_lines_add_to_their_titles_never_repeat_them():
    """ "Loop closure: recognising a place seen before: recognising a place seen before" read twice."""
    for path in site_module.notebook_paths():
        title, line = landing.page_title(path), landing.summary(path)
        words = re.findall(r"[a-z0-9']+", title.lower())
        line_words = " ".join(re.findall(r"[a-z0-9']+", line.lower()))
        repeated = [" ".join(words[k : k + 3]) for k in range(len(words) - 2)]
        repeated = [run for run in repeated if re.search(rf"\b{re.escape(run)}\b", line_words)]
        assert not repeated, f"{path.name}: its line repeats {repeated} of its title {title!r}"


def test_the_landing_page_spells_out_slam_and_separates_title_from_line(tmp_path, monkeypatch):
    code, err, out = _book(tmp_path, monkeypatch, {"09_page.ipynb": ["# 9. A page: what it is\n\nIt teaches."]})
    assert code == 0, err
    html = (out / "index.html").read_text(encoding="utf-8")
    text = " ".join(re.sub(r"<[^>]+>", "", html).split())
    assert "SLAM, simultaneous localisation and mapping" in text
    assert f"9. A page: what it is{landing.SEPARATOR}It teaches." in text


def test_the_search_from_disk_shows_no_excerpts_it_cannot_fetch(tmp_path, monkeypatch):
    code, err, out = _book(tmp_path, monkeypatch, {"01_page.ipynb": ["# 1. A page\n\nSome text."]})
    assert code == 0, err
    options = (out / "_static" / "documentation_options.js").read_text(encoding="utf-8")
    assert re.search(r"SHOW_SEARCH_SUMMARY:\s*false", options), options


# 13. Maths and 15. code to copy: the style and the scripts


def _rule(css: str, selector: str) -> str:
    found = re.search(rf"(?:^|\}}|\n)\s*{re.escape(selector)}\s*\{{([^}}]*)\}}", css)
    assert found, f"book.css has no rule for {selector}"
    return found.group(1)


def test_maths_sits_on_the_line_and_a_wide_formula_scrolls_in_mathjax_2():
    """The theme's flex boxes are for MathJax 3: the book loads MathJax 2.7, so its own style undoes them."""
    assert "mathjax/MathJax.js" in site_module.CONF["mathjax_path"]
    source = Path(__import__("jupyter_server_mathjax").__file__).parent / "static" / "MathJax.js"
    assert re.search(r'MathJax\.version\s*=\s*"2\.7', source.read_text(encoding="utf-8", errors="replace"))
    css = BOOK_CSS.read_text(encoding="utf-8")
    inline = _rule(css, "span.math")
    assert "display: inline;" in inline and "overflow: visible" in inline and "max-width: none" in inline
    assert "display: block" in _rule(css, "div.math")
    assert "overflow-x: auto" in _rule(css, "div.math .MathJax_Display")
    assert "overflow-x: auto" in _rule(css, "article :is(p, li):has(> span.math)")  # MathJax 2 never breaks one


def test_the_texts_code_blocks_have_a_copy_button_and_scroll(tmp_path, monkeypatch):
    cells = ["# 1. A page\n\n```bash\nmake run\n```\n\nText.", "## 1.1 Code\n\n```python\nprint('x')\n```"]
    code, err, out = _book(tmp_path, monkeypatch, {"01_page.ipynb": cells})
    assert code == 0, err
    script = (out / "_static" / "copybutton.js").read_text(encoding="utf-8")
    selector = re.search(r"const COPYBUTTON_SELECTOR = '([^']*)'", script).group(1)
    assert selector == site_module.CONF["copybutton_selector"]
    page = (out / "01_page.html").read_text(encoding="utf-8")
    prose = re.findall(r'<div class="(highlight-(?:bash|python)) notranslate"><div class="highlight"><pre>', page)
    assert prose == ["highlight-bash", "highlight-python"], prose
    assert "div[class*=highlight-]:not(.output) > div.highlight > pre" == selector  # those, not a cell's output
    css = BOOK_CSS.read_text(encoding="utf-8")
    assert re.search(r"article div\.highlight pre[^{]*\{[^}]*overflow-x: auto", css), "long lines do not scroll"


# 14. No text of a picture under 11 px where the book shows it


def test_the_figure_style_keeps_text_at_11_px_in_the_books_column():
    margin_px = 12  # the tight frame show_figure saves around a figure
    width = style.FIGURE_WIDTH * style.DPI + margin_px
    assert width <= style.BOOK_COLUMN_PX + margin_px, "the widest figure is shrunk to the column"
    assert style.shown_text_px(style.TEXT_PT, width) >= style.MIN_TEXT_PX
    assert matplotlib.rcParams["font.size"] >= style.TEXT_PT  # ticks, labels and legends left at their default
    assert style.shown_text_px(style.TEXT_PT, style.FIGURE_WIDTH * style.DPI) == pytest.approx(
        style.TEXT_PT * style.DPI / 72
    )


NAMED_SIZES = {"xx-small", "x-small", "small", "smaller"}


def _literal_sizes(tree) -> list[tuple[int, str, object]]:
    """Every size a figure module writes out: (line, keyword, value) of fontsize=, labelsize=, size= in a
    call, and each figsize's width."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        for keyword in node.keywords:
            value = keyword.value
            if keyword.arg in ("fontsize", "labelsize") and isinstance(value, ast.Constant):
                found.append((node.lineno, keyword.arg, value.value))
            if keyword.arg == "figsize" and isinstance(value, ast.Tuple) and isinstance(value.elts[0], ast.Constant):
                found.append((node.lineno, "figsize", value.elts[0].value))
    return found


def test_no_figure_module_writes_a_type_smaller_or_a_figure_wider_than_the_style_allows():
    small = []
    for module in sorted(VIZ.glob("*.py")):
        for line, keyword, value in _literal_sizes(ast.parse(module.read_text(encoding="utf-8"))):
            too_small = keyword in ("fontsize", "labelsize") and (
                value in NAMED_SIZES or (isinstance(value, int | float) and value < style.TEXT_PT)
            )
            too_wide = keyword == "figsize" and value > style.FIGURE_WIDTH
            if too_small or too_wide:
                small.append(f"{module.name}:{line} {keyword}={value!r}")
    assert not small, "sizes the book would show under 11 px: " + ", ".join(small)


def _trajectory(n=120, bend=0.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3], poses[:, 1, 3] = 220 * np.cos(t) + bend * np.sin(3 * t), 120 * np.sin(t)
    return poses


def _live_view(truth):
    live = LiveView(truth, show=False)
    for k, pose in enumerate(truth):
        step = SimpleNamespace(accepted=True, T_map_sensor=pose, loop=None, node=k, index=3 * k)
        live.update(step, np.random.default_rng(k).random((200, 3)) * [40, 300, 5] - [20, 150, 0])
    return live.figure()


TRUTH, FOLDED = _trajectory(), _trajectory(bend=40.0)
FIELD = SimpleNamespace(
    bounds=(0.0, 400.0, 0.0, 250.0),
    valid=np.ones((50, 80), bool),
    z=np.random.default_rng(0).random((50, 80)),
    labels=np.random.default_rng(1).integers(0, 5, (50, 80)),
)
FIXED = np.random.default_rng(2).random((3000, 3)) * [56, 290, 20] - [28, 145, 0]
# Figures as the notebooks draw them, on made-up values of the same shapes: each drawn when its test runs.
FIGURES = {
    "skip_frames": lambda: sweep_figures.skip_frames_figure(
        np.arange(1, 22, 3),
        np.linspace(0.95, 0.3, 7),
        [120, 50, 24, 11, 13, 10, 0],
        [3, 2.6, 12, 11, 4.4, 3, 5e3],
        [0] * 6 + [1],
    ),
    "bad_edge": lambda: graph_figures.bad_edge_figure(TRUTH, {"kernel: none": FOLDED, "kernel: huber": TRUTH}, (5, 60)),
    "left_out": lambda: graph_figures.left_out_figure(["0-50", "3-120", "7-99"], [0.9, 3.0, 1.2], [357.0, 4.5, 2.0]),
    "kernels": lambda: graph_figures.kernels_figure({"huber": 1.345, "cauchy": 2.0}),
    "loop_weights": lambda: graph_figures.loop_weights_figure(["1-80", "2-90", "5-100"], [0.5, 2, 40], [1, 1, 0.1]),
    "stage_errors": lambda: ground_figures.stage_errors_figure(TRUTH, {"odometry": FOLDED, "optimised": TRUTH}),
    "trials_formula": lambda: parameter_figures.trials_formula_figure(3000, pairs_cap=500),
    "height_field": lambda: render.height_field_figure(FIELD, TRUTH[:, :2, 3] / 2 + [200, 125]),
    "clouds": lambda: registration_figures.clouds_figure(FIXED + [0, 2, 0], FIXED, ("moving, scan 102", "fixed, 99")),
    "profile": lambda: registration_figures.profile_figure(
        FIXED + [1, 0, 3], FIXED, {"before": np.eye(4), "after": np.eye(4)}, y=0.0
    ),
    "live_view": lambda: _live_view(TRUTH),
}


def _shown_text(fig) -> tuple[float, float]:
    """(the smallest text in CSS pixels where the book shows the figure, its width in CSS pixels): drawn as
    show_figure draws it, at DPI in a tight frame, and shrunk to the column if wider."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=style.DPI, bbox_inches="tight")
    width = Image.open(buffer).size[0]
    texts = [text for text in fig.findobj(matplotlib.text.Text) if text.get_visible() and text.get_text().strip()]
    matplotlib.pyplot.close(fig)
    return min(style.shown_text_px(text.get_fontsize(), width) for text in texts), width


@pytest.mark.parametrize("name", list(FIGURES))
def test_a_figure_shown_in_the_book_has_no_text_under_11_px(name):
    smallest, width = _shown_text(FIGURES[name]())
    assert width <= style.BOOK_COLUMN_PX + 12, f"{name} is {width} px wide: the column shrinks it"
    assert smallest >= style.MIN_TEXT_PX, f"{name}: text of {smallest:.1f} px in the book"


@pytest.mark.parametrize("name", ["skip_frames", "bad_edge", "profile"])
def test_the_legends_that_covered_data_sit_outside_the_panels(name):
    """Chapter 4's first figure hid its "default" mark, chapter 6's wrong-edge figure its folded trajectory,
    chapter 3's side view the points of a roof."""
    figure = FIGURES[name]()
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    legends = figure.legends + [ax.get_legend() for ax in figure.axes if ax.get_legend()]
    assert legends, f"{name} has no legend"
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for ax in figure.axes:
            assert not box.overlaps(ax.get_window_extent(renderer)), f"{name}: a legend over a panel"
    matplotlib.pyplot.close(figure)


def test_a_3d_views_text_is_11_px_where_the_book_shows_it():
    """A view shown alone (``explore``) is shrunk to the column; notebook 7 sets two side by side."""
    for window, shown in (((900, 600), min(900, style.BOOK_COLUMN_PX)), ((800, 560), render.PAIR_PX)):
        text_px = style.view_text_px(window[0], shown)
        assert text_px * shown / window[0] >= style.MIN_TEXT_PX, (window, shown, text_px)
    points = np.random.default_rng(0).random((500, 3)) * [400, 250, 30]
    plotter = render._plotter((800, 560))
    render.draw_cloud(plotter, points, title="a view", text_px=25)
    bar = plotter.scalar_bars[next(iter(plotter.scalar_bars.keys()))]
    sizes = [bar.GetLabelTextProperty().GetFontSize(), bar.GetTitleTextProperty().GetFontSize()]
    triad = plotter.renderer.axes_actor
    sizes += [c.GetCaptionTextProperty().GetFontSize() for c in (triad.GetXAxisCaptionActor2D(),
              triad.GetYAxisCaptionActor2D(), triad.GetZAxisCaptionActor2D())]  # fmt: skip
    plotter.close()
    assert min(sizes) >= 25, f"text of the view drawn smaller than asked: {sizes}"


def test_an_animation_is_shown_at_the_size_its_frames_are_drawn():
    """Its text is then as large as a figure's: 10 pt at the figures' DPI, 11 px."""
    assert style.TEXT_PT * FRAME_DPI / 72 >= style.MIN_TEXT_PX
    scans = [np.random.default_rng(k).normal(size=(500, 3)) * [20, 150, 5] for k in range(2)]
    html = scan_player(scans, range(2))
    width = int(re.search(r'<img id="_anim_img\w*" width="(\d+)"', html).group(1))
    frame = re.search(r'frames\[0\] = "data:image/jpeg;base64,([^"]+)"', html).group(1)
    assert Image.open(io.BytesIO(base64.b64decode(frame))).size[0] == width


def test_an_animation_with_figure_metadata_is_a_numbered_figure_with_its_caption(tmp_path, monkeypatch):
    """The scan player and the main loop's frames: a cell's ``mystnb.figure`` numbers them as it does a picture."""
    folder = tmp_path / "notebooks"
    folder.mkdir()
    figure = {"caption": "Every 30th scan, seen from the drone.", "name": "fig-01-player"}
    cell = nbformat.v4.new_code_cell("HTML(player)", metadata={"mystnb": {"figure": figure}})
    shown = '<div class="animation"><img id="_anim_imgabc" width="600"></div>'
    cell.outputs = [nbformat.v4.new_output("display_data", data={"text/html": shown, "text/plain": "<HTML>"})]
    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# 1. A page"), cell])
    notebook.metadata["language_info"] = {"name": "python"}
    nbformat.write(notebook, folder / "01_page.ipynb")
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)
    code, err = _site(tmp_path / "html")
    assert code == 0, err
    html = (tmp_path / "html" / "01_page.html").read_text(encoding="utf-8")
    found = re.search(r'<figure[^>]*id="fig-01-player">(.*?)</figure>', html, re.DOTALL)
    assert found and 'id="_anim_imgabc"' in found.group(1), "the animation is not inside its figure"
    assert "Figure 1.1" in found.group(1) and figure["caption"] in found.group(1)
    assert 'alt="1. A page, figure 1.1, an animation"' in found.group(1)


def test_the_script_of_the_landing_pictures_calls_what_the_package_has():
    """``notebooks/figures/readme_figure.py`` draws the README's and the landing page's picture; it is run by
    hand, so a move in the package could leave it broken unseen (it was, once): every name it imports from
    ``helpers`` exists, and every keyword it passes to a figure function is one that function takes."""
    import importlib
    import inspect

    script = ROOT / "notebooks" / "figures" / "readme_figure.py"
    tree = ast.parse(script.read_text())
    modules = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module.startswith("helpers"):
            module = importlib.import_module(node.module)
            for alias in node.names:
                try:  # a name of the module, or a submodule of the package
                    found = getattr(module, alias.name, None) or importlib.import_module(f"{node.module}.{alias.name}")
                except ImportError:
                    found = None
                assert found is not None, f"{node.module} has no {alias.name}"
                modules[alias.asname or alias.name] = found
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)]
    checked = 0
    for call in calls:
        owner = call.func.value
        if isinstance(owner, ast.Name) and owner.id in modules:
            function = getattr(modules[owner.id], call.func.attr)
            parameters = inspect.signature(function).parameters
            assert all(k.arg in parameters for k in call.keywords), f"{call.func.attr} takes no {call.keywords}"
            checked += 1
    assert checked >= 1
