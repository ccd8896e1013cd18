"""The static site, exported from the committed notebooks without running
them: every page is linked in order, every picture is embedded and shows
something, and the scan player carries its frames with it."""

import base64
import io
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers.site import build_site, notebook_paths

CHROMIUM = Path("/usr/bin/chromium")
FRAME = re.compile(r'frames\[\d+\] = "(data:image/[^"]+)"')
ANIMATION_IMG = "_anim_img"  # id prefix of the <img> a matplotlib animation draws its frames into


class _Page(HTMLParser):
    """Collects the links and the images of one page."""

    def __init__(self):
        super().__init__()
        self.links: list[str] = []
        self.images: list[dict] = []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "a" and "href" in attrs:
            self.links.append(attrs["href"])
        elif tag == "img":
            self.images.append(attrs)


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


def _assert_screenshot_not_blank(path: Path):
    image = np.asarray(Image.open(path).convert("RGB"), dtype=float)
    assert image.std() > 2.0, f"{path.name} looks blank (pixel std {image.std():.2f})"


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


def test_pages_render_in_a_headless_browser(site, tmp_path):
    if not CHROMIUM.exists():
        pytest.skip(f"no browser at {CHROMIUM}: the headless rendering check needs Debian's chromium")
    for page in (site, site.parent / "01_dataset.html"):
        shot = tmp_path / f"{page.stem}.png"
        profile = tmp_path / f"profile-{page.stem}"
        subprocess.run(
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
                f"--screenshot={shot}",
                "--window-size=1200,900",
                page.resolve().as_uri(),
            ],
            check=True,
            capture_output=True,
            timeout=180,
        )
        shutil.rmtree(profile, ignore_errors=True)
        assert shot.is_file(), f"chromium wrote no screenshot of {page.name}"
        _assert_screenshot_not_blank(shot)
