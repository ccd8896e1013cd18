"""The notebooks' own section numbers in the book (hooks of ``sphinx_ext``).

The notebooks number their headings by hand ("## 3.4 Matching descriptors",
"### 3.4.1 ..."), as JupyterLab shows them. The book checks those numbers
against each heading's place (chapter 3's second-level headings are 3.1, 3.2,
... in order, the third-level ones under 3.4 are 3.4.1, 3.4.2, ...): a number
given twice or out of order stops the build and says which number the heading
should have, so the book never shows two sections "3.4.1".

Each numbered heading gets a second anchor, ``#section-3-4``, that survives a
change of its title, and each exercise heading ``#exercise-3-1``. In the text,
"section 3.4" (also "sections 3.4 and 3.5") and "exercise 3.2" become links
to that anchor, on whichever page it is; a link to a notebook right after the
mention ("section 3.4 of [notebook 3](...)") goes to the section too, and a
worked answers page's link to its chapter goes to the chapter's exercises. A
cited section no heading has stops the build, as a broken link does.
"""

from __future__ import annotations

import re
from pathlib import PurePosixPath

from docutils import nodes
from sphinx.util import logging

log = logging.getLogger(__name__)

CHAPTER = re.compile(r"(\d+)_")  # notebooks/03_registration.ipynb is chapter 3
SOLUTIONS = "solutions"
NUMBER = r"\d+\.\d+(?:\.\d+)*"
NUMBERED = re.compile(r"(?P<number>\d+(?:\.\d+)*)\.?\s")  # "3.4 Matching descriptors", "3. Registration"
EXERCISE = re.compile(rf"Exercise\s+(?P<number>{NUMBER})\b")  # "Exercise 3.1: what MSAC scores"
EXERCISES = "Exercises"  # the heading of a chapter's exercises, where its worked answers link back to
# "section 3.4", "Sections 3.4 and 3.5", "sections 2.5-2.7", "exercise 3.2"; not "a section 0.5 m wide".
UNIT = r"(?!\s*(?:m|cm|mm|km|s|ms|%|°|deg)\b)"
MENTION = re.compile(
    rf"\b(?P<word>[Ss]ections?|[Ee]xercises?)\s+(?P<numbers>{NUMBER}{UNIT}"
    rf"(?:(?:,\s*|,?\s+and\s+|,?\s+or\s+|\s+to\s+|\s*[-\u2013]\s*){NUMBER}{UNIT})*)"
)
ONE_NUMBER = re.compile(NUMBER)
THEN_LINK = re.compile(r"\s+(?:of|in)\s+$")  # "section 3.4 of " followed by a link to the notebook
# Where a mention stays text: headings, links, code, formulas, raw HTML.
NOT_IN = (nodes.title, nodes.reference, nodes.literal, nodes.FixedTextElement, nodes.raw, nodes.math, nodes.target)


def chapter_of(docname: str) -> str | None:
    """ "3" for chapter 3's page; None for its worked answers, the landing page or any other page."""
    path = PurePosixPath(docname)
    found = CHAPTER.match(path.name)
    return str(int(found.group(1))) if found and path.parent.name != SOLUTIONS else None


def anchor(kind: str, number: str) -> str:
    """The anchor of section or exercise ``number``: "section-3-4", "exercise-3-1"."""
    return f"{kind}-{number.replace('.', '-')}"


def _level(section: nodes.section) -> int:
    level, parent = 1, section.parent
    while parent is not None:
        level += isinstance(parent, nodes.section)
        parent = parent.parent
    return level


def collect_headings(app, doctree) -> None:
    """On ``doctree-read``: a chapter's headings (kind, number, level, title, anchor), in order, kept in the
    environment; each numbered heading and each exercise gets its anchor."""
    docname = app.env.docname
    headings = getattr(app.env, "helpers_headings", {})
    app.env.helpers_headings = headings
    headings.pop(docname, None)
    if chapter_of(docname) is None:
        return
    found = []
    for section in doctree.findall(nodes.section):
        title = section[0].astext() if section.children and isinstance(section[0], nodes.title) else ""
        numbered, exercise = NUMBERED.match(title), EXERCISE.match(title)
        if numbered:
            kind, number = "section", numbered.group("number")
        elif exercise:
            kind, number = "exercise", exercise.group("number")
        elif title.strip() == EXERCISES:
            kind, number = "exercises", ""
        else:
            kind, number = "plain", ""
        name = anchor(kind, number) if number else section["ids"][0] if section["ids"] else ""
        if number and name not in section["ids"]:
            section["ids"].append(name)
        found.append((kind, number, _level(section), title, name))
    headings[docname] = found


def purge_headings(app, env, docname: str) -> None:
    getattr(env, "helpers_headings", {}).pop(docname, None)


def merge_headings(app, env, docnames, other) -> None:
    env.helpers_headings = getattr(env, "helpers_headings", {})
    env.helpers_headings.update({d: h for d, h in getattr(other, "helpers_headings", {}).items() if d in docnames})


def number_problems(chapter: str, headings: list[tuple]) -> list[str]:
    """What is wrong with a chapter's section numbers, each as one sentence (none: all in order)."""
    problems, seen = [], {}
    counts = {1: 0, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0}
    parents: dict[int, str | None] = {1: chapter}
    for kind, number, level, title, _ in headings:
        if kind != "section":  # an unnumbered heading: the numbered ones under it have nothing to follow
            parents[level] = None
            for deeper in range(level + 1, 7):
                counts[deeper], parents[deeper] = 0, None
            continue
        if level == 1:
            expected = chapter
        elif parents.get(level - 1) is None:
            problems.append(f'section number {number} of "{title}": the heading above it has no number')
            continue
        else:
            counts[level] += 1
            expected = f"{parents[level - 1]}.{counts[level]}"
        if number != expected:
            twice = f', which "{seen[number]}" has already' if number in seen else ""
            problems.append(f'section number {number} of "{title}" should be {expected} by its place{twice}')
        seen.setdefault(number, title)
        parents[level] = expected
        for deeper in range(level + 1, 7):  # a new section starts its subsections' count again
            counts[deeper], parents[deeper] = 0, None
    return problems


def check_numbers(app, env) -> list[str]:
    """On ``env-updated``: every chapter's numbers checked (a problem is a warning the build treats as
    fatal), and the book's table of what each number and exercise links to."""
    targets = {}
    for docname, headings in sorted(getattr(env, "helpers_headings", {}).items()):
        for problem in number_problems(chapter_of(docname), headings):
            log.warning(problem, location=docname)
        for kind, number, _, _, name in headings:
            if kind == "plain":
                continue
            targets.setdefault((kind, number or chapter_of(docname)), (docname, name))
    env.helpers_section_targets = targets
    return []


def _uri(app, docname: str, target: tuple[str, str]) -> str:
    page, name = target
    return f"#{name}" if page == docname else f"{app.builder.get_relative_uri(docname, page)}#{name}"


def _kind(word: str) -> str:
    return "section" if word.lower().startswith("section") else "exercise"


def link_mentions(app, doctree, docname: str) -> None:
    """On ``doctree-resolved``: "section 3.4" and "exercise 3.2" in the text become links to their headings,
    and links to a chapter carry the anchor the text around them names."""
    targets = getattr(app.env, "helpers_section_targets", {})
    texts = [text for text in doctree.findall(nodes.Text) if not _inside(text, NOT_IN)]
    for text in texts:
        if MENTION.search(text.astext()):
            _link_in(app, text, docname, targets)
    _answers_link_to_exercises(app, doctree, docname, targets)


def _inside(node, kinds) -> bool:
    parent = node.parent
    while parent is not None:
        if isinstance(parent, kinds):
            return True
        parent = parent.parent
    return False


def _link_in(app, text: nodes.Text, docname: str, targets: dict) -> None:
    source, pieces, last_target, at = text.astext(), [], None, 0
    for mention in MENTION.finditer(source):
        kind = _kind(mention.group("word"))
        for number in ONE_NUMBER.finditer(mention.group("numbers")):
            start = mention.start("numbers") + number.start()
            start = mention.start() if number.start() == 0 else start  # the first link holds "section"
            end = mention.start("numbers") + number.end()
            target = targets.get((kind, number.group()))
            if target is None:
                log.warning(f"{kind} {number.group()} is cited, but no heading has that number", location=docname)
                continue
            pieces += [nodes.Text(source[at:start]), _reference(source[start:end], _uri(app, docname, target))]
            at, last_target = end, target
    if not pieces:
        return
    rest = source[at:]
    pieces.append(nodes.Text(rest))
    following = text.parent[text.parent.index(text) + 1] if text.parent.index(text) + 1 < len(text.parent) else None
    if THEN_LINK.fullmatch(rest) and isinstance(following, nodes.reference) and last_target is not None:
        uri = following.get("refuri", "")
        if uri and "#" not in uri and uri == app.builder.get_relative_uri(docname, last_target[0]):
            following["refuri"] = f"{uri}#{last_target[1]}"
    text.parent.replace(text, pieces)


def _reference(label: str, uri: str) -> nodes.reference:
    return nodes.reference("", label, internal=True, refuri=uri, classes=["section-mention"])


def _answers_link_to_exercises(app, doctree, docname: str, targets: dict) -> None:
    """A worked answers page's links to its own chapter land on the chapter's exercises."""
    path = PurePosixPath(docname)
    found = CHAPTER.match(path.name)
    if path.parent.name != SOLUTIONS or found is None:
        return
    target = targets.get(("exercises", str(int(found.group(1)))))
    if target is None:
        return
    uri = app.builder.get_relative_uri(docname, target[0])
    for reference in doctree.findall(nodes.reference):
        if reference.get("refuri") == uri:
            reference["refuri"] = f"{uri}#{target[1]}"
