"""The book, built from the committed notebooks without running them: a
landing page with the result and a line per page, the whole book in every
page's sidebar, previous/next links in reading order, a search, every picture
a local file that shows something, the scan player with its frames, and
nothing asked of the network. Then a headless Chromium opens every page from
disk: it renders, its formulas are typeset, its pictures load, it requests
nothing off the machine, and the search page finds a word of a notebook.
Chapter 2's parameter table is a table, code cells have a copy button, cell
tags fold or drop cells and admonitions are boxes."""

import base64
import io
import json
import re
import time
import zipfile
from contextlib import redirect_stderr
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import nbformat
import numpy as np
import pytest
from PIL import Image

from helpers.__main__ import main
from helpers.site import archive, build_site, notebook_paths, solution_paths
from helpers.site import build as site_module
from helpers.site import sphinx_ext as site_ext
from helpers.site.landing import summary as page_summary

FRAME = re.compile(r'frames\[\d+\] = "(data:image/[^"]+)"')
ANIMATION_IMG = "_anim_img"  # id prefix of the <img> a matplotlib animation draws its frames into
OFF_MACHINE = re.compile(r"^(https?:|wss?:|ftp:)?//", re.IGNORECASE)
CSS_URL = re.compile(r"url\(\s*['\"]?([^'\")]+)")


class _Page(HTMLParser):
    """Collects one page's links (and where they sit), images and loaded resources."""

    def __init__(self):
        super().__init__()
        self.links: list[str] = []  # every <a href>
        self.sidebar: list[str] = []  # <a href> of the book's navigation (the left sidebar)
        self.previous: list[str] = []
        self.next: list[str] = []
        self.images: list[dict] = []
        self.resources: list[str] = []  # what a browser loads: scripts, style sheets, pictures, frames, fonts
        self.main: list[str] = []  # <a href> inside the page's article
        self._nav_depth = 0
        self._article_depth = 0

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        classes = (attrs.get("class") or "").split()
        if tag == "nav":
            self._nav_depth += self._nav_depth > 0 or "bd-docs-nav" in classes
        if tag == "article":
            self._article_depth += 1
        if tag == "a" and "href" in attrs:
            href = attrs["href"]
            self.links.append(href)
            if self._nav_depth:
                self.sidebar.append(href)
            if self._article_depth:
                self.main.append(href)
            if "left-prev" in classes:
                self.previous.append(href)
            if "right-next" in classes:
                self.next.append(href)
        elif tag == "img":
            self.images.append(attrs)
            if attrs.get("src"):
                self.resources.append(attrs["src"])
        elif tag in ("script", "iframe", "source", "video", "audio", "embed") and attrs.get("src"):
            self.resources.append(attrs["src"])
        elif tag == "link" and attrs.get("href"):
            self.resources.append(attrs["href"])
        elif tag == "object" and attrs.get("data"):
            self.resources.append(attrs["data"])

    def handle_endtag(self, tag):
        if tag == "nav" and self._nav_depth:
            self._nav_depth -= 1
        if tag == "article" and self._article_depth:
            self._article_depth -= 1


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


class _Tables(HTMLParser):
    """Collects a page's tables, each a list of rows of cell texts."""

    def __init__(self):
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr" and self.tables:
            self.tables[-1].append([])
        elif tag in ("td", "th"):
            self._cell = []

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None and self.tables and self.tables[-1]:
            self.tables[-1][-1].append("".join(self._cell).strip())
            self._cell = None


class _Headings(HTMLParser):
    """Collects the headings of a page's article as (level, text), without their "#" permalinks."""

    def __init__(self):
        super().__init__()
        self.headings: list[tuple[int, str]] = []
        self._level = 0
        self._text: list[str] = []
        self._in_link = False
        self._article = 0

    def handle_starttag(self, tag, attrs):
        self._article += tag == "article"
        if self._article and re.fullmatch(r"h[1-6]", tag):
            self._level, self._text = int(tag[1]), []
        self._in_link = self._in_link or (tag == "a" and "headerlink" in (dict(attrs).get("class") or ""))

    def handle_data(self, data):
        if self._level and not self._in_link:
            self._text.append(data)

    def handle_endtag(self, tag):
        self._article -= tag == "article" and self._article > 0
        if tag == "a":
            self._in_link = False
        if self._level and tag == f"h{self._level}":
            self.headings.append((self._level, "".join(self._text).strip()))
            self._level = 0


def _headings(page: Path) -> list[tuple[int, str]]:
    parser = _Headings()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser.headings


class _Figures(HTMLParser):
    """Collects a page's pictures: each <img>'s alt text, the id of the <figure> holding it (None if none)
    and that figure's caption number ("Figure 3.2"), from the article only."""

    def __init__(self):
        super().__init__()
        self.pictures: list[dict] = []
        self._figures: list[dict] = []  # the open <figure> elements, innermost last
        self._number: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "figure":
            self._figures.append({"id": attrs.get("id"), "number": ""})
        elif tag == "span" and "caption-number" in (attrs.get("class") or "") and self._figures:
            self._number = []
        elif tag == "img":
            figure = self._figures[-1] if self._figures else None
            self.pictures.append({"alt": attrs.get("alt"), "id": attrs.get("id", ""), "figure": figure})

    def handle_data(self, data):
        if self._number is not None:
            self._number.append(data)

    def handle_endtag(self, tag):
        if tag == "span" and self._number is not None:
            self._figures[-1]["number"] = "".join(self._number).strip()
            self._number = None
        elif tag == "figure" and self._figures:
            self._figures.pop()


def _pictures(page: Path) -> list[dict]:
    parser = _Figures()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser.pictures


def _local(page: Path, href: str) -> Path | None:
    """The file a relative link of ``page`` points to (None for an in-page anchor)."""
    target = unquote(urlsplit(href).path)
    return (page.parent / target).resolve() if target else None


def _assert_picture(image: Image.Image, where: str):
    pixels = np.asarray(image.convert("RGB"), dtype=float)
    assert pixels.shape[0] > 10 and pixels.shape[1] > 10, f"{where}: image of {pixels.shape[:2]} pixels"
    assert pixels.std() > 2.0, f"{where}: image is blank (pixel std {pixels.std():.2f})"


def _data_picture(uri: str, where: str):
    assert uri.startswith("data:image/"), f"{where}: not an embedded image ({uri[:60]!r})"
    header, _, payload = uri.partition(",")
    assert header.endswith(";base64"), f"{where}: image not base64 ({header!r})"
    _assert_picture(Image.open(io.BytesIO(base64.b64decode(payload))), where)


def _colourful_share(path: Path) -> float:
    """Share of a screenshot's pixels in strong colour: text and code are
    black, grey or faintly tinted; the maps and plots are colourful."""
    image = np.asarray(Image.open(path).convert("RGB"), dtype=int)
    return float(np.mean(image.max(axis=2) - image.min(axis=2) > 60))


@pytest.fixture(scope="module")
def book(tmp_path_factory) -> Path:
    """The book from the committed outputs; the checkout's notebooks folder is left as it was."""
    before = sorted(p.relative_to(site_module.NOTEBOOKS) for p in site_module.NOTEBOOKS.rglob("*"))
    start = time.perf_counter()
    index = build_site(tmp_path_factory.mktemp("book") / "html", execute=False)
    print(f"book built in {time.perf_counter() - start:.1f} s")
    assert sorted(p.relative_to(site_module.NOTEBOOKS) for p in site_module.NOTEBOOKS.rglob("*")) == before
    return index


def _pages(book: Path) -> list[Path]:
    """The book's pages in reading order: the landing page, the notebooks, the solutions."""
    chapters = [book.parent / p.with_suffix(".html").name for p in notebook_paths()]
    solutions = [book.parent / site_module.SOLUTIONS / p.with_suffix(".html").name for p in solution_paths()]
    return [book, *chapters, *solutions]


def test_the_landing_page_shows_the_result_and_every_page_in_order(book):
    pages = _pages(book)
    for page in pages:
        assert page.is_file(), f"{page.name} is missing"
    landing = _parse(book)
    pages_linked = [href for href in landing.main if urlsplit(href).path.endswith(".html")]
    listed = [str(_local(book, href)) for href in pages_linked if _local(book, href) not in (None, book.resolve())]
    assert listed == [str(p.resolve()) for p in pages[1:]], "the landing page lists the pages out of order"
    pictures = [attrs["src"] for attrs in landing.images if "result" in attrs.get("src", "")]
    assert pictures, "the landing page has no result picture"
    _assert_picture(Image.open(book.parent / pictures[0]), "the landing page's picture")
    text = book.read_text(encoding="utf-8").replace("\u2019", "'")
    for path in notebook_paths():  # each page's line says what it teaches
        assert page_summary(path) in text, f"no line about {path.name}"
    headings = [heading for level, heading in _headings(book) if level == 2]
    assert headings[:3] == ["What you will learn", "Before you start", "Running the notebooks yourself"], headings
    words = " ".join(re.sub(r"<[^>]+>", " ", text).split())  # code spans break a command into tags
    for needed in ("numpy", "linear algebra", "roughly an hour", "make run", "make test", "make lab", "pip install",
                   "jupyter lab", "helpers", "simultaneous localisation and mapping"):  # fmt: skip
        assert needed in words, f"the landing page does not mention {needed!r}"


def test_every_page_has_the_whole_book_in_its_sidebar_and_its_neighbours_linked(book):
    pages = _pages(book)
    for number, page in enumerate(pages):
        parsed = _parse(page)
        sidebar = {_local(page, href) or page.resolve() for href in parsed.sidebar}
        missing = [p.name for p in pages if p.resolve() not in sidebar]
        assert not missing, f"{page.name}'s sidebar lacks {missing}"
        previous = [_local(page, href) for href in parsed.previous]
        following = [_local(page, href) for href in parsed.next]
        assert previous == ([pages[number - 1].resolve()] if number else []), f"{page.name}: previous {previous}"
        last = number == len(pages) - 1
        assert following == ([] if last else [pages[number + 1].resolve()]), f"{page.name}: next {following}"


def test_every_link_between_pages_resolves(book):
    for page in [*_pages(book), book.parent / "search.html", book.parent / "genindex.html"]:
        for href in _parse(page).links:
            if OFF_MACHINE.match(href) or href.startswith(("mailto:", "javascript:")):
                continue  # a reference the reader may follow; never loaded by the page itself
            target = _local(page, href)
            assert target is None or target.is_file(), f"{page.name} links {href}, which the book lacks"


def test_every_link_to_a_place_in_a_page_finds_its_anchor(book):
    """A link to section 3.4 lands on it, not at the top of a 32,000 px page: every "#anchor" exists."""
    ids = {}
    checked = 0
    for page in [*_pages(book), book.parent / "search.html"]:
        for href in _parse(page).links:
            parts = urlsplit(href)
            if OFF_MACHINE.match(href) or not parts.fragment or href.startswith(("mailto:", "javascript:")):
                continue
            target = _local(page, href) or page.resolve()
            if target not in ids:
                ids[target] = set(re.findall(r'\bid="([^"]+)"', target.read_text(encoding="utf-8")))
            assert unquote(parts.fragment) in ids[target], f"{page.name} links {href}: no such anchor"
            checked += 1
    assert checked > 100, f"only {checked} links to anchors"


MENTION = re.compile(r"\b[Ss]ections? \d+\.\d+")


def test_section_mentions_are_links_and_cross_page_links_carry_anchors(book):
    """The text's "section 3.4" links to the section, on its page or another; none is left as plain text."""
    linked, plain = 0, []
    for page in _pages(book)[1:]:
        html = page.read_text(encoding="utf-8")
        article = html[html.index("<article") : html.index("</article>")]
        article = re.sub(r"<(pre|code|script|h[1-6])\b.*?</\1>", "", article, flags=re.DOTALL)  # no links there
        mentions = re.findall(r'<a class="section-mention[^"]*" href="([^"]+)">', article)
        linked += len(mentions)
        assert all("#" in href for href in mentions), f"{page.name}: a mention without an anchor"
        text = re.sub(r"<a [^>]*>.*?</a>", "", article, flags=re.DOTALL)
        plain += [f"{page.name}: {m}" for m in MENTION.findall(re.sub(r"<[^>]+>", "", text))]
    assert linked > 50, f"only {linked} section mentions are links"
    assert not plain, f"mentions left as text: {plain[:5]}"
    across = [href for page in _pages(book)[1:] for href in _parse(page).main
              if re.match(r"(\.\./)?0\d_\w+\.html#", href)]  # fmt: skip
    assert len(across) > 20, f"only {len(across)} links between pages carry an anchor"


def test_no_two_headings_of_the_book_share_a_section_number(book):
    """Chapter 3 once showed two sections "3.4.1"."""
    seen = {}
    for page in _pages(book)[1:9]:
        for _, heading in _headings(page):
            number = re.match(r"(\d+(?:\.\d+)+)\s", heading)
            if number:
                assert number.group(1) not in seen, f"{number.group(1)} on {page.name} and {seen[number.group(1)]}"
                seen[number.group(1)] = page.name
    assert len(seen) > 50, f"only {len(seen)} numbered headings"


def test_the_landing_page_offers_the_project_and_repeats_no_title(book):
    """The zip holds the notebooks, the package and what the README's commands need; nothing built or
    installed. Each page's line says what its title does not."""
    zipped = book.parent / archive.ARCHIVE
    assert archive.ARCHIVE in _parse(book).main, "the landing page does not link the project"
    with zipfile.ZipFile(zipped) as opened:
        names = [name.removeprefix(f"{archive.NAME}/") for name in opened.namelist()]
    for needed in ("README.md", "Makefile", "environment.txt", "pyproject.toml", "LICENSE", "helpers/__init__.py",
                   "notebooks/figures/result.png", "data/aerialMap.tar.gz"):  # fmt: skip
        assert needed in names, f"the project's archive lacks {needed}"
    notebooks = [p.relative_to(site_module.NOTEBOOKS.parent).as_posix() for p in [*notebook_paths(), *solution_paths()]]
    assert set(notebooks) <= set(names), "the archive lacks a notebook or a worked answer"
    assert not [n for n in names if n.split("/")[0] in ("build", ".venv") or "__pycache__" in n], "built files"
    text = book.read_text(encoding="utf-8")
    for line in re.findall(r'<li><p><a class="reference internal" href="0\d[^"]*">(.*?)</a>(.*?)</p></li>', text):
        title, said = (" ".join(re.sub(r"<[^>]+>", "", part).split()) for part in line)
        subtitle = title.split(":", 1)[-1].strip()
        assert subtitle.lower() not in said.lower(), f"the line of {title!r} repeats it: {said!r}"


def test_every_picture_is_a_local_file_that_shows_something(book):
    for page in _pages(book):
        for number, attrs in enumerate(_parse(page).images):
            where = f"{page.name}, image {number}"
            source = attrs.get("src", "")
            if attrs.get("id", "").startswith(ANIMATION_IMG) and not source:
                continue  # an animation's frames live in its script (checked below)
            if source.startswith("data:"):
                _data_picture(source, where)
                continue
            path = _local(page, source)
            assert path is not None and path.is_file(), f"{where}: {source} is missing"
            _assert_picture(Image.open(path), where)


def test_the_scan_player_is_embedded_with_its_frames(book):
    page = book.parent / "01_dataset.html"
    images = _parse(page).images
    assert any(attrs.get("id", "").startswith(ANIMATION_IMG) for attrs in images), "no animation in 01"
    frames = FRAME.findall(page.read_text(encoding="utf-8"))
    assert len(frames) > 5, f"the scan player has {len(frames)} frames"
    for number, uri in enumerate(frames):
        assert uri.startswith("data:image/jpeg;base64,"), f"frame {number} is not an embedded JPEG"
        _data_picture(uri, f"scan player frame {number}")


def test_pages_and_style_sheets_load_nothing_from_the_network(book):
    """A page opened from disk with no network must not need a CDN: MathJax,
    the theme's fonts and icons are the book's own files."""
    root = book.parent
    pages = [*_pages(book), root / "search.html", root / "genindex.html"]
    for page in pages:
        for resource in _parse(page).resources:
            assert not OFF_MACHINE.match(resource), f"{page.name} loads {resource} from the network"
            local = None if resource.startswith("data:") else _local(page, resource)
            assert local is None or local.is_file(), f"{page.name} loads {resource}, which the book lacks"
    for sheet in root.glob("_static/**/*.css"):
        for url in CSS_URL.findall(sheet.read_text(encoding="utf-8", errors="replace")):
            assert not OFF_MACHINE.match(url), f"{sheet.relative_to(root)} loads {url} from the network"
    assert (root / "_static" / "mathjax" / "MathJax.js").is_file()


def test_the_search_index_holds_the_notebooks_words(book):
    root = book.parent
    assert (root / "search.html").is_file()
    text = (root / "searchindex.js").read_text(encoding="utf-8")
    index = json.loads(text[text.index("(") + 1 : text.rindex(")")])
    assert "06_pose_graph" in index["docnames"]
    assert "gtsam" in index["terms"], "the search index lacks a word of notebook 6"


def test_chapter_2s_parameter_table_is_a_table(book):
    """The table is a Markdown output of a cell: myst-nb's default (CommonMark) renders it as a paragraph of pipes."""
    page = book.parent / "02_parameters.html"
    parser = _Tables()
    parser.feed(page.read_text(encoding="utf-8"))
    tables = [rows for rows in parser.tables if rows and rows[0][:3] == ["stage", "parameter", "default"]]
    assert len(tables) == 1, f"02_parameters has {len(tables)} parameter tables among {len(parser.tables)} tables"
    rows = tables[0]
    assert len(rows) > 30 and all(len(row) == len(rows[0]) == 5 for row in rows), "the parameter table's shape"
    assert ["grid_step", "1.5"] in [row[1:3] for row in rows], "the table lacks grid_step's default"
    assert "|---|" not in page.read_text(encoding="utf-8")


HASH_OR_FILE = re.compile(r"[0-9a-f]{16}|\.(png|jpe?g|gif|svg)$", re.IGNORECASE)


def test_every_picture_has_a_text_alternative_not_a_file_name(book):
    """Docutils gives a picture without alt text its file name, for myst-nb a hash: the build gives the page's
    title and the figure's number (or the picture's place) instead, where the notebook gave none."""
    for page in _pages(book):
        for number, picture in enumerate(_pictures(page)):
            alt = (picture["alt"] or "").strip()
            assert alt and not HASH_OR_FILE.search(alt), f"{page.name}, picture {number}: alt text {alt!r}"


def test_every_figure_a_notebook_draws_has_its_own_caption_and_alt_text(book):
    """The notebooks' convention: a cell whose output is a figure carries
    ``mystnb: {figure: {caption, name}, image: {alt}}``, so the book shows "Figure N.k" and a caption under the
    picture, and a reader who cannot see it hears what it shows. The scan player (an animation in raw HTML)
    cannot take cell metadata: its alt text is the build's."""
    lacking = []
    for page in _pages(book)[1:]:
        title = _headings(page)[0][1]
        chapter = site_ext.chapter_label(page.relative_to(book.parent).with_suffix("").as_posix())
        for number, picture in enumerate(_pictures(page)):
            if picture["id"].startswith(ANIMATION_IMG):
                continue
            figure, alt = picture["figure"], picture["alt"] or ""
            if figure is None or not re.fullmatch(rf"Figure {chapter}\.\d+", figure["number"]):
                lacking.append(f"{page.name} picture {number}: no numbered caption")
            if alt.startswith(title):
                lacking.append(f"{page.name} picture {number}: no alt text of its own")
    assert not lacking, f"{len(lacking)} pictures lack a caption or alt text:\n" + "\n".join(lacking)


# In a headless browser, from disk: one Chromium for all pages.


# Resolves, with the number of typeset formulas, once MathJax's first typesetting of the page has ended and
# the fonts it asked for have loaded (the hook returns nothing: MathJax would wait on what it returns).
MATHJAX_DONE = """new Promise(done => {
  if (!document.querySelector('.math')) return done(0);
  const count = () => document.querySelectorAll('script[type^="math/tex"]').length;
  const wait = () => (window.MathJax && MathJax.Hub && MathJax.Hub.Register)
    ? MathJax.Hub.Register.StartupHook('End', () => { document.fonts.ready.then(() => done(count())); })
    : setTimeout(wait, 50);
  wait();
})"""
PAGE_STATE = """(() => {
  const article = document.querySelector('article');
  const prose = article ? article.cloneNode(true) : document.createElement('div');
  prose.querySelectorAll('pre, code, script, style').forEach(e => e.remove());
  return {
    title: document.title,
    text: article ? article.innerText.length : 0,
    untypeset: [...document.querySelectorAll('.math.nohighlight')]  // Sphinx's; MathJax's own output has .math too
      .filter(e => !e.querySelector('.MathJax, .MathJax_Display')).map(e => e.textContent.slice(0, 60)),
    errors: document.querySelectorAll('.MathJax_Error, .merror').length,
    raw: ['$', '\\\\(', '\\\\['].filter(d => prose.textContent.includes(d)),  // '$': a $$ block myst did not read
    broken: [...document.images].filter(i => i.src && !(i.complete && i.naturalWidth > 0)).map(i => i.src),
    images: document.images.length,
  };
})()"""


def test_every_page_renders_offline_with_its_formulas_typeset(book, browser):
    for page in [*_pages(book), book.parent / "search.html"]:
        browser.open(page.resolve().as_uri())
        browser.evaluate(MATHJAX_DONE)
        state = browser.evaluate(PAGE_STATE)
        name = page.relative_to(book.parent)
        assert (state["title"] and state["text"] > 100) or page.name == "search.html", f"{name} shows no text"
        assert not state["broken"], f"{name}: pictures that did not load: {state['broken']}"
        assert not state["untypeset"], f"{name}: formulas left as TeX: {state['untypeset']}"
        assert not state["errors"], f"{name}: {state['errors']} formulas MathJax could not read"
        assert not state["raw"], f"{name}: untypeset TeX delimiters {state['raw']} in its text"
        leaving = [url for url in browser.requested() if not url.startswith(("file:", "data:", "about:"))]
        assert not leaving, f"{name} asked the network for {leaving}"
        assert not browser.failed(), f"{name} could not load {browser.failed()}"
        thrown = [e["params"]["exceptionDetails"] for e in browser.events if e["method"] == "Runtime.exceptionThrown"]
        assert not thrown, f"{name}: script errors {thrown}"


def test_the_pose_graph_formulas_are_typeset(book, browser):
    browser.open((book.parent / "06_pose_graph.html").resolve().as_uri())
    assert browser.evaluate(MATHJAX_DONE) >= 10, "MathJax typeset fewer than 10 formulas on 06_pose_graph"


def test_a_display_formula_inside_a_list_item_is_typeset(book, browser):
    """Chapter 4's relative pose error, a display formula in its own paragraph of a bullet."""
    browser.open((book.parent / "04_submaps.html").resolve().as_uri())
    browser.evaluate(MATHJAX_DONE)
    found = browser.evaluate("""[...document.querySelectorAll('article li')]
      .filter(item => [...item.querySelectorAll('script[type^="math/tex"]')].some(s => s.text.includes('E_i =')))
      .map(item => ({display: item.querySelectorAll('.MathJax_Display').length,
                     dollars: item.innerText.includes('$')}))""")
    assert found == [{"display": 1, "dollars": False}], f"the RPE formula in its bullet: {found}"


def test_chapter_2s_parameter_table_fits_the_text_column_on_a_desktop(book, browser):
    browser.resize(1300, 900)
    browser.open((book.parent / "02_parameters.html").resolve().as_uri())
    table, column = browser.evaluate("""(() => {
      const table = document.querySelector('article table');
      return [table.getBoundingClientRect().width, document.querySelector('article').getBoundingClientRect().width];
    })()""")
    assert table <= column, f"the parameter table is {table:.0f} px wide in a {column:.0f} px column"


def test_code_cells_have_a_copy_button_from_the_books_own_script(book, browser):
    page = book.parent / "03_registration.html"
    loaded = [unquote(urlsplit(src).path) for src in _parse(page).resources]
    scripts = [path for path in loaded if "clipboard" in path or "copybutton" in path]
    assert {Path(s).name for s in scripts} >= {"clipboard.min.js", "copybutton.js", "copybutton.css"}, scripts
    assert all((page.parent / s).is_file() for s in scripts), f"copy button files missing: {scripts}"
    browser.resize(1300, 900)
    browser.open(page.resolve().as_uri())
    cells = browser.evaluate("""[...document.querySelectorAll('div.cell_input')].map(cell => {
      const button = cell.querySelector('button.copybtn');
      const target = button && document.querySelector(button.dataset.clipboardTarget);
      return button ? target.innerText || target.textContent : null;  // a folded cell's code is hidden
    })""")
    code = [cell.source for cell in nbformat.read(site_module.NOTEBOOKS / page.with_suffix(".ipynb").name, 4).cells
            if cell.cell_type == "code"]  # fmt: skip
    assert len(cells) == len(code) and None not in cells, f"{cells.count(None)} of {len(cells)} code cells lack one"
    assert [text.strip() for text in cells] == [source.strip() for source in code], "a button copies other text"
    x, y = browser.evaluate("""(() => {
      const button = document.querySelector('div.cell_input button.copybtn');
      button.scrollIntoView({block: 'center'});
      const r = button.getBoundingClientRect();
      return [r.left + r.width / 2, r.top + r.height / 2];
    })()""")
    browser.click(x, y)
    copied = browser.evaluate("""new Promise(done => setTimeout(() =>
      done(document.querySelector('div.cell_input button.copybtn').dataset.tooltip), 300))""")
    assert copied == "Copied!", f"clicking the copy button says {copied!r}"


def test_the_search_page_finds_a_word_of_a_notebook(book, browser):
    browser.open((book.parent / "search.html").resolve().as_uri() + "?q=gtsam")
    found = browser.evaluate("""new Promise(done => {
      const start = Date.now();
      const poll = () => {
        const hits = [...document.querySelectorAll('#search-results li a')].map(a => a.getAttribute('href'));
        (hits.length || Date.now() - start > 10000) ? done(hits) : setTimeout(poll, 100);
      };
      poll();
    })""")
    assert any(hit.startswith("06_pose_graph.html") for hit in found), f"searching gtsam found {found}"


def test_the_pictures_show_in_the_browser(book, browser, tmp_path):
    browser.resize(1300, 900)
    browser.open(book.resolve().as_uri())
    landing = browser.screenshot(tmp_path / "index.png")
    image = np.asarray(Image.open(landing).convert("L"), dtype=float)
    assert image.std() > 2.0, f"the landing page looks blank (pixel std {image.std():.2f})"

    browser.open((book.parent / "07_map_comparison.html").resolve().as_uri())
    browser.evaluate(MATHJAX_DONE)  # the page's layout settles once its formulas are typeset
    count = browser.evaluate("document.querySelectorAll('article img').length")
    assert count >= 3, f"the map-comparison page shows {count} pictures"
    for number in range(3):
        box = browser.evaluate(f"""(() => {{
          const image = document.querySelectorAll('article img')[{number}];
          image.scrollIntoView({{block: 'center'}});
          const r = image.getBoundingClientRect();
          return {{x: r.left + scrollX, y: r.top + scrollY, width: r.width, height: r.height}};
        }})()""")
        assert box["width"] > 100 and box["height"] > 100, f"picture {number} of 07 is drawn {box}"
        painted = browser.screenshot(tmp_path / f"picture{number}.png", box)
        share = _colourful_share(painted)
        assert share > 0.05, f"picture {number} of 07 shows {share:.1%} colourful pixels in the browser"


# Whether the page scrolls sideways, and which boxes stick out of the window without a scroll bar of their own.
SIDEWAYS = """(() => {
  const width = document.documentElement.clientWidth;
  const scrolls = e => { for (let a = e.parentElement; a && a !== document.body; a = a.parentElement)
    if (getComputedStyle(a).overflowX !== 'visible') return true; return false; };
  const out = [...document.querySelectorAll('article *')].filter(e => e.getBoundingClientRect().right > width + 1
    && e.checkVisibility() && !scrolls(e)).map(e => e.tagName + ' ' + (e.textContent || '').slice(0, 40));
  const squashed = [...document.querySelectorAll('article img')].filter(i => i.checkVisibility() && i.naturalWidth)
    .filter(i => { const r = i.getBoundingClientRect(), shape = i.naturalHeight / i.naturalWidth;
                   return Math.abs(r.height / r.width - shape) > 0.02 * shape; })
    .map(i => i.alt);
  const cut = [...document.querySelectorAll('article button, article input')].filter(e => e.checkVisibility())
    .filter(e => e.getBoundingClientRect().right > width + 1).map(e => e.title || e.className);
  return {page: document.documentElement.scrollWidth, window: width, out: out.slice(0, 5), squashed, cut};
})()"""


def test_no_page_scrolls_sideways_on_a_phone(book, browser):
    """At 400 px, long code, printed lines and tables scroll inside their own boxes and long code named in the
    prose breaks: the page itself is never wider than the window. Pictures shrink to it in their own shape, and
    the scan player's buttons stay within reach."""
    browser.resize(400, 800)
    try:
        for page in [*_pages(book), book.parent / "search.html"]:
            browser.open(page.resolve().as_uri())
            browser.evaluate(MATHJAX_DONE)
            state = browser.evaluate(SIDEWAYS)
            assert state["page"] <= state["window"], f"{page.name} scrolls sideways at 400 px: {state}"
            assert not state["out"], f"{page.name}: boxes run off a 400 px window: {state['out']}"
            assert not state["squashed"], f"{page.name}: pictures out of shape: {state['squashed']}"
            assert not state["cut"], f"{page.name}: controls beyond the window's edge: {state['cut']}"
    finally:
        browser.resize(1300, 900)


# Each visible code box: whether it scrolls, and its longest line's length.
CODE_BOXES = """[...document.querySelectorAll('div.cell_input pre')].filter(p => p.checkVisibility())
  .map(p => [p.scrollWidth > p.clientWidth + 1, Math.max(...p.innerText.split('\\n').map(l => l.length))])"""


def test_a_code_line_of_88_characters_fits_its_box_on_a_laptop_screen(book, browser):
    """The notebooks keep code lines to 88 characters: on a 1366 px wide screen such a line shows whole,
    and only a box holding a longer line scrolls."""
    browser.resize(1366, 800)
    try:
        for page in _pages(book)[1:]:
            browser.open(page.resolve().as_uri())
            boxes = browser.evaluate(CODE_BOXES)
            cut = [longest for scrolls, longest in boxes if scrolls and longest <= 88]
            assert not cut, f"{page.name}: {len(cut)} code boxes scroll with lines of at most {max(cut)} characters"
    finally:
        browser.resize(1300, 900)


# MathJax 2 inside the theme's boxes for MathJax 3: where each inline formula's baseline sits against the line's
# (a zero-size box before the formula sits on the line's baseline, one inside MathJax's own box on the
# formula's), and each display formula's natural width against the box it is shown in, and whether that scrolls.
MATHS = """(() => {
  const mark = () => {
    const m = document.createElement('span');
    m.style.cssText = 'display:inline-block;width:0;height:0';
    return m;
  };
  const offsets = [...document.querySelectorAll('article p > span.math')].map(s => {
    const inner = s.querySelector('.MathJax span.math'); if (!inner) return null;
    const a = mark(), b = mark(); s.before(a); inner.append(b);
    const [ra, rb, f] = [a.getBoundingClientRect(), b.getBoundingClientRect(), inner.getBoundingClientRect()];
    a.remove();
    b.remove();
    return f.left >= ra.left - 1 ? ra.bottom - rb.bottom : null;  // null: the line broke before the formula
  }).filter(o => o !== null);
  const displays = [...document.querySelectorAll('article div.math .MathJax_Display')].map(box => {
    const formula = box.querySelector('span.MathJax > nobr > span.math');
    const natural = formula.firstElementChild.getBoundingClientRect().width;
    return {natural, shown: formula.getBoundingClientRect().width, box: box.clientWidth,
            scrolls: box.scrollWidth >= natural - 1 && getComputedStyle(box).overflowX === 'auto'};
  });
  return {offsets, displays};
})()"""


def test_inline_formulas_sit_on_the_line_and_wide_ones_scroll_on_a_phone(book, browser):
    """The theme's span.math flex box raised inline formulas about 4 px and cut display formulas wider than a
    400 px phone, with no scroll bar: the book's style sets them right for the MathJax 2 it loads."""
    try:
        for width in (1366, 400):
            browser.resize(width, 900)
            wide = 0
            for name in ("03_registration.html", "06_pose_graph.html", "08_your_own_ground.html"):
                browser.open((book.parent / name).resolve().as_uri())
                browser.evaluate(MATHJAX_DONE)
                assert browser.evaluate("MathJax.version").startswith("2.7")
                state = browser.evaluate(MATHS)
                assert len(state["offsets"]) > 10 and max(map(abs, state["offsets"])) < 0.6, f"{name}: {state}"
                for formula in state["displays"]:
                    assert formula["shown"] >= formula["natural"] - 1, f"{name} at {width} px: a formula cut {formula}"
                    if formula["natural"] > formula["box"] + 1:
                        wide += 1
                        assert formula["scrolls"], f"{name} at {width} px: a wide formula does not scroll {formula}"
            assert wide or width > 1000, "no formula wider than a phone: this test checks nothing"
    finally:
        browser.resize(1300, 900)


def test_the_texts_code_blocks_have_a_copy_button_too(book, browser):
    """The landing page's two commands, chapter 1's call for your own data."""
    browser.resize(1366, 900)
    for page in (book, book.parent / "01_dataset.html"):
        browser.open(page.resolve().as_uri())
        blocks = browser.evaluate("""[...document.querySelectorAll('article div.highlight')]
          .filter(d => !d.closest('.cell_input, .cell_output'))
          .map(d => [!!d.querySelector('button.copybtn'), getComputedStyle(d.querySelector('pre')).overflowX])""")
        assert blocks and all(button and scroll == "auto" for button, scroll in blocks), f"{page.name}: {blocks}"


def test_the_books_column_on_a_laptop_shows_a_figure_whole(book, browser):
    """The figures are drawn style.FIGURE_WIDTH wide at style.DPI for a column of style.BOOK_COLUMN_PX: on a
    1366 px screen the column is at least that wide, so their text is shown at its size, 11 px or more."""
    from helpers.viz import style

    browser.resize(1366, 900)
    browser.open((book.parent / "06_pose_graph.html").resolve().as_uri())
    column = browser.evaluate("document.querySelector('article section > p').getBoundingClientRect().width")
    assert column >= style.BOOK_COLUMN_PX, f"the column is {column:.0f} px: figures would be shrunk"
    assert style.FIGURE_WIDTH * style.DPI <= column


def test_a_printed_sentence_wraps_on_a_laptop_and_a_printed_table_scrolls_on_a_phone(book, browser):
    """The worked answers' "correct: ..." lines were cut at 1366 px; on a phone printed lines keep their columns."""
    page = (book.parent / "solutions" / "03_registration_solutions.html").resolve().as_uri()
    cut = """[...document.querySelectorAll('div.cell_output div.output.stream pre')].filter(p => p.checkVisibility())
      .map(p => [p.scrollWidth > p.clientWidth + 1, getComputedStyle(p).whiteSpace])"""
    try:
        browser.resize(1366, 900)
        browser.open(page)
        outputs = browser.evaluate(cut)
        assert outputs and not any(scrolls for scrolls, _ in outputs), f"printed lines cut at 1366 px: {outputs}"
        browser.resize(400, 800)
        browser.open(page)
        assert {space for _, space in browser.evaluate(cut)} == {"pre"}, "printed lines wrap on a phone"
    finally:
        browser.resize(1300, 900)


def test_printed_pages_wrap_long_lines_instead_of_cutting_them(book, browser):
    """On paper nothing scrolls: a code line too long for the column wraps inside its box."""
    browser.resize(1300, 900)
    browser.open((book.parent / "07_map_comparison.html").resolve().as_uri())
    widest = "Math.max(...[...document.querySelectorAll('div.cell pre')].map(e => e.scrollWidth - e.clientWidth))"
    assert browser.evaluate(widest) > 0, "no code line of 07 is longer than its box: this test checks nothing"
    browser.call("Emulation.setEmulatedMedia", session=True, media="print")
    try:
        assert browser.evaluate(widest) <= 0, "a printed code line runs past its box"
    finally:
        browser.call("Emulation.setEmulatedMedia", session=True, media="")


# The output folder: replaced only when it is empty or an earlier site (checked on a one-page book, not executed).


@pytest.fixture()
def one_notebook(tmp_path, monkeypatch):
    """The book's notebooks are one small notebook in a folder of its own (no solutions)."""
    import nbformat.v4

    folder = tmp_path / "notebooks"
    folder.mkdir()
    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# A page\n\nSome text, $x^2$.")])
    nbformat.write(notebook, folder / "01_page.ipynb")
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)
    return folder


def _site(out) -> tuple[int, str]:
    """``python -m helpers site --out OUT --no-execute`` in this process: (exit code, stderr)."""
    with redirect_stderr(io.StringIO()) as err:
        code = main(["site", "--out", str(out), "--no-execute"])
    return code, err.getvalue()


def test_the_site_refuses_a_folder_that_holds_a_users_files(tmp_path, one_notebook):
    out = tmp_path / "home" / "Documents"
    out.mkdir(parents=True)
    (out / "thesis.txt").write_text("three years of work")
    code, err = _site(out)
    assert code == 2
    assert err.strip().splitlines() == [
        f"error: output folder {out} is not empty and holds no earlier {site_module.MARKER}: choose another"
    ]
    assert [p.name for p in out.iterdir()] == ["thesis.txt"]
    assert (out / "thesis.txt").read_text() == "three years of work"
    assert [p.name for p in out.parent.iterdir()] == ["Documents"]  # no half-written site beside it


def test_the_site_refuses_the_current_folder(tmp_path, one_notebook, monkeypatch):
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)
    (here / "notes.md").write_text("mine")
    assert _site(".")[0] == 2 and (here / "notes.md").read_text() == "mine"
    (here / "notes.md").unlink()
    code, err = _site(".")  # even empty: replacing it would leave the shell in a deleted folder
    assert code == 2 and "holds the current folder" in err
    assert here.is_dir() and not any(here.iterdir())


def test_the_site_fills_an_empty_folder_and_replaces_an_earlier_site(tmp_path, one_notebook):
    out = tmp_path / "build" / "html"
    out.mkdir(parents=True)
    assert _site(out)[0] == 0
    assert (out / "01_page.html").is_file() and (out / site_module.MARKER).is_file()
    assert "01_page.html" in _parse(out / "index.html").main
    assert "Appendix" not in (out / "index.html").read_text(encoding="utf-8")  # no solutions, no appendix
    import nbformat.v4

    gone = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# A page the next build drops")])
    nbformat.write(gone, one_notebook / "02_gone.ipynb")
    assert _site(out)[0] == 0 and (out / "02_gone.html").is_file()
    (one_notebook / "02_gone.ipynb").unlink()
    assert _site(out)[0] == 0
    assert not (out / "02_gone.html").exists() and (out / "01_page.html").is_file()  # a stale page goes
    assert [p.name for p in out.parent.iterdir()] == ["html"]  # no temporary folders, nothing of myst-nb's
    (out / "notes.html").write_text("the user's own page")  # but a page the book did not write stays
    code, err = _site(out)
    assert code == 2 and "holds 1 file(s) this tool did not write (notes.html)" in err
    assert (out / "notes.html").read_text() == "the user's own page" and (out / "01_page.html").is_file()


def test_the_solutions_are_the_books_appendix(tmp_path, one_notebook):
    import nbformat.v4

    (one_notebook / "solutions").mkdir()
    answer = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# Solutions to page 1\n\nThe answers.")])
    nbformat.write(answer, one_notebook / "solutions" / "01_page_solutions.ipynb")
    out = tmp_path / "html"
    assert _site(out)[0] == 0
    index = _parse(out / "index.html")
    assert index.main.index("01_page.html") < index.main.index("solutions/01_page_solutions.html")
    page = out / "solutions" / "01_page_solutions.html"
    assert page.is_file()
    assert [_local(page, href) for href in _parse(page).previous] == [(out / "01_page.html").resolve()]
    assert "Appendix: solutions" in page.read_text(encoding="utf-8")  # the sidebar's caption


def test_a_broken_link_fails_the_build_and_leaves_the_folder_alone(tmp_path, one_notebook):
    import nbformat.v4

    broken = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# B\n\nSee [it](09_missing.ipynb).")])
    nbformat.write(broken, one_notebook / "02_broken.ipynb")
    out = tmp_path / "html"
    code, err = _site(out)
    assert code == 2 and "09_missing.ipynb" in err and "02_broken.ipynb" in err
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["notebooks"]


def test_the_notebooks_run_in_a_kernel_that_draws_3d_views_as_pictures(tmp_path, one_notebook):
    import nbformat.v4

    cell = nbformat.v4.new_code_cell("import os\nprint('views:', os.environ.get('HELPERS_3D'))")
    nbformat.write(nbformat.v4.new_notebook(cells=[cell]), one_notebook / "02_run.ipynb")
    out = tmp_path / "html"
    assert main(["site", "--out", str(out)]) == 0  # executed, as by make run
    assert "views: static" in (out / "02_run.html").read_text(encoding="utf-8")
    assert not nbformat.read(one_notebook / "02_run.ipynb", as_version=4).cells[0].outputs  # the checkout's copy


# Jupyter Book's cell tags and admonitions, on a page made for them: the tags fold a cell away (a <details> the
# reader opens, no script needed) or drop it, and a note or tip shows as a box.
TAGGED = {"hide-input": "shown output", "hide-cell": "output of a folded cell", "remove-cell": "output never shown"}


@pytest.fixture()
def tagged_page(tmp_path, one_notebook) -> Path:
    import nbformat.v4

    cells = [nbformat.v4.new_markdown_cell("# Tags\n\n```{note}\nA note.\n```\n\n:::{tip}\nA tip.\n:::")]
    for tag, printed in TAGGED.items():
        source = f"print({printed.upper()!r}.lower())  # {tag}"  # what it prints is not in its source
        cell = nbformat.v4.new_code_cell(source, metadata={"tags": [tag]})
        cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=printed + "\n")]
        cells.append(cell)
    notebook = nbformat.v4.new_notebook(cells=cells, metadata={"language_info": {"name": "python"}})
    nbformat.write(notebook, one_notebook / "02_tags.ipynb")
    assert _site(tmp_path / "html")[0] == 0
    return tmp_path / "html" / "02_tags.html"


def test_cell_tags_fold_or_drop_cells_and_admonitions_are_boxes(tagged_page):
    html = tagged_page.read_text(encoding="utf-8")
    assert "remove-cell" not in html and TAGGED["remove-cell"] not in html
    folded = re.findall(r"<details.*?</details>", html, re.DOTALL)
    assert len(folded) == 2, f"{len(folded)} folded parts"
    assert "# hide-input" in folded[0] and TAGGED["hide-input"] not in folded[0] and TAGGED["hide-input"] in html
    assert "# hide-cell" in folded[1] and TAGGED["hide-cell"] in folded[1]
    assert 'class="admonition note"' in html and 'class="admonition tip"' in html


def test_a_folded_cell_opens_in_the_browser(tagged_page, browser):
    browser.open(tagged_page.resolve().as_uri())
    shown = """[...document.querySelectorAll('div.cell')].map(cell =>
      [cell.querySelector('.cell_input').checkVisibility(), cell.querySelector('.cell_output').checkVisibility()])"""
    assert browser.evaluate(shown) == [[False, True], [False, False]]
    for summary in range(2):
        browser.evaluate(f"document.querySelectorAll('details summary')[{summary}].click()")
    assert browser.evaluate(shown) == [[True, True], [True, True]]
    leaving = [url for url in browser.requested() if not url.startswith(("file:", "data:", "about:"))]
    assert not leaving, f"the page asked the network for {leaving}"
