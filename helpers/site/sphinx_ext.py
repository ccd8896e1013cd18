"""The book's own Sphinx extension, loaded by the generated conf.py.

- Figures are numbered by chapter: the second captioned figure of notebook 3 is
  "Figure 3.2" (Sphinx alone counts on across the whole book, since our
  toctree is not numbered: the notebooks number their own headings). A worked
  answers page's figures are "Figure S3.1"; the landing page's are not
  numbered.
- Every picture has a text alternative. A notebook gives one with its cell's
  ``mystnb: {image: {alt: ...}}`` metadata; a picture without one would get
  its file name, a hash, as alt text, so it gets the page's title and its
  figure number (or its place on the page) instead. The same holds for a
  picture inside an output's raw HTML, such as the scan player's frame; a
  cell's ``mystnb.figure`` metadata makes an animation a numbered figure with
  its caption as it does a picture.
- A picture a cell shows links to its own file, so a phone's reader can open
  it alone and zoom (Sphinx links a picture shown smaller than drawn, as
  ``show_figure``'s are; the others are marked so it links them too).
- The notebooks' own section numbers are checked, and "section 3.4" in the
  text links to its heading (``sections``).
"""

from __future__ import annotations

import html
import re
from pathlib import PurePosixPath

from docutils import nodes

from helpers.site import sections

CHAPTER = re.compile(r"(\d+)_")  # notebooks/03_registration.ipynb is chapter 3
SOLUTIONS = "solutions"
IMG_WITHOUT_ALT = re.compile(r"<img(?![^>]*\balt=)", re.IGNORECASE)
ANIMATION = 'id="_anim_img'  # the <img> a matplotlib animation (the scan player) draws its frames into


def setup(app):
    app.connect("env-get-updated", number_figures_by_chapter, priority=900)  # after Sphinx numbered them (500)
    app.connect("doctree-resolved", give_every_picture_alt_text)
    app.connect("doctree-resolved", link_output_pictures_to_their_files)
    app.connect("doctree-read", sections.collect_headings)
    app.connect("env-purge-doc", sections.purge_headings)
    app.connect("env-merge-info", sections.merge_headings)
    app.connect("env-updated", sections.check_numbers)
    app.connect("doctree-resolved", sections.link_mentions)
    return {"parallel_read_safe": True, "parallel_write_safe": True}


def chapter_label(docname: str) -> str | None:
    """The label of a page's figures: "3" for chapter 3, "S3" for its worked answers, None for another page."""
    path = PurePosixPath(docname)
    found = CHAPTER.match(path.name)
    if found is None:
        return None
    number = str(int(found.group(1)))
    return f"S{number}" if path.parent.name == SOLUTIONS else number


def number_figures_by_chapter(app, env) -> list[str]:
    """Renumbers each page's figures (and tables, code listings) as (chapter, rank on the page); a page of no
    chapter (the landing page) shows its captions unnumbered."""
    for docname, by_type in env.toc_fignumbers.items():
        chapter = chapter_label(docname)
        for numbers in by_type.values():
            if chapter is None:
                numbers.clear()
                continue
            in_page_order = sorted(numbers, key=numbers.get)  # Sphinx counted in reading order
            numbers.update({key: (chapter, rank) for rank, key in enumerate(in_page_order, start=1)})
    return []


def figure_number(env, docname: str, image: nodes.Element) -> str | None:
    """The number of the captioned figure holding ``image`` (or an output's raw HTML), as the page shows it
    ("3.2"), or None."""
    figure = image.parent
    while figure is not None and not isinstance(figure, nodes.figure):
        figure = figure.parent
    if figure is None or not figure["ids"]:
        return None
    number = env.toc_fignumbers.get(docname, {}).get("figure", {}).get(figure["ids"][0])
    return ".".join(map(str, number)) if number else None


def give_every_picture_alt_text(app, doctree, docname: str) -> None:
    title = app.env.titles[docname].astext() if docname in app.env.titles else docname
    for place, image in enumerate(doctree.findall(nodes.image), start=1):
        if image.get("alt", "").strip():
            continue
        number = figure_number(app.env, docname, image)
        image["alt"] = f"{title}, figure {number}" if number else f"{title}, picture {place}"
    for raw in doctree.findall(nodes.raw):
        if "html" not in raw.get("format", "").split():
            continue
        text = raw.astext()
        if IMG_WITHOUT_ALT.search(text):
            what = "an animation" if ANIMATION in text else "a picture in an output"
            number = figure_number(app.env, docname, raw)  # a cell's mystnb.figure makes it a figure too
            alt = html.escape(f"{title}, figure {number}, {what}" if number else f"{title}, {what}", quote=True)
            raw.clear()
            raw += nodes.Text(IMG_WITHOUT_ALT.sub(f'<img alt="{alt}"', text))


def _in_cell_output(node) -> bool:
    while node is not None:
        if "cell_output" in node.get("classes", []):
            return True
        node = node.parent
    return False


def link_output_pictures_to_their_files(app, doctree, docname: str) -> None:
    """Marks a cell's picture with no size of its own as shown at full scale: Sphinx's HTML builder then
    links it to its file, as it does for the pictures shown smaller than drawn."""
    for image in doctree.findall(nodes.image):
        if not any(key in image for key in ("scale", "width", "height")) and _in_cell_output(image):
            image["scale"] = 100
