"""The static site, exported from the committed notebooks without running
them: every page is linked in order, every picture is embedded and shows
something, the scan player carries its frames with it, nothing comes from
the network, and a headless browser shows the pictures and the formulas."""

import base64
import io
import re
import shutil
import subprocess
import tempfile
from contextlib import redirect_stderr
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers.__main__ import main
from helpers.site import build as site_module
from helpers.site import build_site, notebook_paths

CHROMIUM = Path("/usr/bin/chromium")
FRAME = re.compile(r'frames\[\d+\] = "(data:image/[^"]+)"')
ANIMATION_IMG = "_anim_img"  # id prefix of the <img> a matplotlib animation draws its frames into


class _Page(HTMLParser):
    """Collects the links, the images and the loaded resources of one page."""

    def __init__(self):
        super().__init__()
        self.links: list[str] = []
        self.images: list[dict] = []
        self.resources: list[str] = []  # what the browser loads: scripts, style sheets

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "a" and "href" in attrs:
            self.links.append(attrs["href"])
        elif tag == "img":
            self.images.append(attrs)
        elif tag == "script" and attrs.get("src"):
            self.resources.append(attrs["src"])
        elif tag == "link" and attrs.get("href"):
            self.resources.append(attrs["href"])


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


def _assert_picture(uri: str, where: str):
    """A data URI that decodes to an image with more than one colour."""
    assert uri.startswith("data:image/"), f"{where}: image not embedded ({uri[:60]!r})"
    header, _, payload = uri.partition(",")
    assert header.endswith(";base64"), f"{where}: image not base64 ({header!r})"
    image = np.asarray(Image.open(io.BytesIO(base64.b64decode(payload))).convert("RGB"), dtype=float)
    assert image.shape[0] > 10 and image.shape[1] > 10, f"{where}: image of {image.shape[:2]} pixels"
    assert image.std() > 2.0, f"{where}: image is blank (pixel std {image.std():.2f})"


def _colourful_share(path: Path) -> float:
    """Share of a screenshot's pixels in strong colour: text and code are
    black, grey or faintly tinted; the maps and plots are colourful."""
    image = np.asarray(Image.open(path).convert("RGB"), dtype=int)
    return float(np.mean(image.max(axis=2) - image.min(axis=2) > 60))


def _chromium(page: Path, tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    """Headless Chromium on ``page``, with no network and a fresh profile;
    ``--virtual-time-budget`` lets the page's scripts (MathJax) finish first."""
    profile = tempfile.mkdtemp(prefix="chromium-profile-", dir=tmp_path)
    try:
        return subprocess.run(
            [
                str(CHROMIUM),
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                f"--user-data-dir={profile}",
                "--virtual-time-budget=10000",
                *args,
                page.resolve().as_uri(),
            ],
            check=True,
            capture_output=True,
            text=True,
            timeout=180,
        )
    finally:
        shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    return build_site(tmp_path_factory.mktemp("site") / "html", execute=False)


def test_index_links_every_notebook_page_in_order(site):
    expected = [path.with_suffix(".html").name for path in notebook_paths()]
    assert site.name == "index.html"
    assert _parse(site).links == expected
    for page in expected:
        assert (site.parent / page).is_file(), f"{page} is linked but missing"


def test_every_image_is_embedded_and_shows_something(site):
    for page in _parse(site).links:
        parsed = _parse(site.parent / page)
        for number, attrs in enumerate(parsed.images):
            if attrs.get("id", "").startswith(ANIMATION_IMG) and "src" not in attrs:
                continue  # an animation's frames live in its script (checked below)
            _assert_picture(attrs.get("src", ""), f"{page}, image {number}")


def test_the_scan_player_is_embedded_with_its_frames(site):
    page = site.parent / "01_dataset.html"
    images = _parse(page).images
    assert any(attrs.get("id", "").startswith(ANIMATION_IMG) for attrs in images), "no animation in 01"
    frames = FRAME.findall(page.read_text(encoding="utf-8"))
    assert len(frames) > 5, f"the scan player has {len(frames)} frames"
    for number, uri in enumerate(frames):
        assert uri.startswith("data:image/jpeg;base64,"), f"frame {number} is not an embedded JPEG"
        _assert_picture(uri, f"scan player frame {number}")


def test_pages_load_nothing_from_the_network(site):
    """Opened from disk with no network, a page must not need a CDN: MathJax
    is the site's own copy, the scan player's icons are characters."""
    for page in ["index.html", *_parse(site).links]:
        for resource in _parse(site.parent / page).resources:
            assert not re.match(r"(https?:)?//", resource), f"{page} loads {resource} from the network"
            local = site.parent / resource.split("?")[0]
            assert local.is_file(), f"{page} loads {resource}, which the site lacks"


@pytest.fixture()
def browser():
    if not CHROMIUM.exists():
        pytest.skip(f"no browser at {CHROMIUM}: this check needs Debian's chromium (make test installs it as root)")


def test_pages_render_with_their_pictures_in_a_headless_browser(site, tmp_path, browser):
    index = tmp_path / "index.png"
    _chromium(site, tmp_path, f"--screenshot={index}", "--window-size=1000,700")
    image = np.asarray(Image.open(index).convert("L"), dtype=float)
    assert image.std() > 2.0, f"the index page looks blank (pixel std {image.std():.2f})"

    stage = tmp_path / "stage.png"  # tall enough for the first three pictures of the page
    _chromium(site.parent / "07_map_comparison.html", tmp_path, f"--screenshot={stage}", "--window-size=1000,3000")
    share = _colourful_share(stage)
    assert share > 0.05, f"the map-comparison page shows {share:.1%} colourful pixels: its pictures did not render"


def test_the_formulas_are_typeset_offline(site, tmp_path, browser):
    page = site.parent / "06_pose_graph.html"
    dom = _chromium(page, tmp_path, "--dump-dom").stdout
    source = page.read_text(encoding="utf-8")
    assert "$$" in source, "the pose-graph page has no display formula to typeset"
    typeset = dom.count('class="MathJax"')  # a typeset formula (HTML-CSS output)
    assert typeset >= 10, f"MathJax typeset {typeset} formulas on {page.name}"


# The output folder: replaced only when it is empty or an earlier site (checked on a one-page site, not executed).


@pytest.fixture()
def one_notebook(tmp_path, monkeypatch):
    """The site's notebooks are one small notebook in a folder of its own."""
    import nbformat.v4

    folder = tmp_path / "notebooks"
    folder.mkdir()
    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell("# A page\n\nSome text.")])
    nbformat.write(notebook, folder / "01_page.ipynb")
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)


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
    assert _parse(out / "index.html").links == ["01_page.html"]
    (out / "stale.html").write_text("from an older build")
    assert _site(out)[0] == 0
    assert not (out / "stale.html").exists() and (out / "01_page.html").is_file()
    assert [p.name for p in out.parent.iterdir()] == ["html"]  # no temporary folders left
