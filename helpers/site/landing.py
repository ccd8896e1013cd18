"""The book's landing page: what the reader will learn, what they need to know
first, how long it takes, how to run the notebooks themselves (the project
to download, and the README's two commands), and a line per page saying what
it teaches, linked, in reading order."""

from __future__ import annotations

import re
from pathlib import Path

TITLE = "Aerial lidar SLAM, step by step"
SOLUTIONS = "solutions"  # notebooks/solutions/*.ipynb: the book's appendix, and its folder in the book
RESULT_PICTURE = Path("figures") / "result.png"  # the landing page's picture (the README's)

# What each page teaches, one line on the landing page after the page's title (by the notebook's number; a
# notebook not listed here gets the first sentence of its introduction). A line adds to its title, never
# repeats it: the titles already say "the map, a flight and a lidar", "recognising a place seen before".
SUMMARIES = {
    "01": (
        "the two input files the reference starts from; the lidar's fan of rays; one scan cast by hand with "
        "Open3D, then the whole flight; what the scanner sees of the ground"
    ),
    "02": "a picture per parameter, and which defaults are the reference's and which are ours",
    "03": (
        "FPFH features, matching, Kabsch, MSAC and ICP, each checked against the truth and set beside the "
        "library call that does it; each parameter swept on the pair"
    ),
    "04": "how the errors of each step add up over the whole flight, tracking, and scans merged into submaps",
    "05": "candidate submaps, the checks a loop edge must pass, and the reference's main loop written out",
    "06": "one loop edge on a line, the same chain in GTSAM factor by factor, then our graph and a robust kernel",
    "07": "the map scored point by point, and the reference's workflow against ours on the same flight",
    "08": (
        "a sparse tile flown low, where the reference's values lose the track; how sure each step is, drawn "
        "along the track; a motion factor and GNSS fixes added to the graph factor by factor"
    ),
}
SEPARATOR = " \u2014 "  # between a page's title and its line: titles hold colons of their own

INTRODUCTION = """\
A drone flies over an aerial map and scans the ground with a lidar. These pages rebuild, one stage a page,
the whole pipeline of SLAM, simultaneous localisation and mapping, that turns those scans into a
trajectory (where the drone was) and a map (what it saw): registration of scan pairs, submaps, loop
closure and a pose graph, each measured against the ground truth the simulator keeps.
"""

RESULT = f"""\
```{{figure}} {RESULT_PICTURE.as_posix()}
:alt: the default flight: ground truth, odometry only, and the trajectory after loop closure

Where the book ends: the odometry alone (red) drifts away from the true flight (green); after loop
closure and pose-graph optimisation (blue) the trajectory lies back on it.
```
"""

GOALS = """\
## What you will learn

- how a lidar scan is simulated from an aerial map, and what the scanner sees of the ground below it;
- how two scans are registered: FPFH descriptors, feature matching, a robust rigid fit (MSAC) and ICP,
  each checked against the true motion;
- why chaining those motions (odometry) drifts, and how submaps and loop closures find the places
  flown over twice;
- how a pose graph, built in GTSAM factor by factor, spreads a loop's correction over the whole flight,
  and how a robust kernel protects it from a wrong loop;
- how to score the rebuilt map against the truth, and where the reference workflow and ours differ;
- what changes on ground unlike the default, and how motion and GNSS factors help there.

## Before you start

You need Python (functions, loops, calling a class's methods), numpy (arrays, indexing, broadcasting)
and a little linear algebra (matrix products, rotation matrices, least squares). No lidar or SLAM
background is assumed: each idea is explained before the cell that uses it.

Reading a page and running its cells takes roughly an hour, longer with its exercises; the registration
and pose-graph pages are the densest. The first notebook that needs the whole SLAM run computes it once,
which takes a few minutes on a laptop (more on a slow machine); later pages read it from a cache.
"""

RUNNING = """\
## Running the notebooks yourself

These pages are the notebooks as they were last executed. To run them, change them and do the exercises,
download the project: {link}{size}. It holds the `helpers` package the notebooks call, the notebooks with
their worked answers, the Makefile, the pinned packages (`environment.txt`), and the README, `docs/` and
`benchmarks/` that the pages name. Unzip it and, in its folder, on Debian with Python 3.11, run the
README's two commands:

```bash
make run    # the dataset, the whole SLAM run and this book, on the embedded default
make test   # lint, unit tests, and nbval re-running every notebook
```

Each creates `.venv/` and installs the pinned packages into it on first use (a few minutes, about 2.5 GB).
Open3D needs Debian's `libusb-1.0-0` and off-screen rendering `libosmesa6`: run as root, `make` installs
them; otherwise it names what is missing. Then `make lab` opens the notebooks in JupyterLab: start with the
first. In an environment of your own instead: `pip install -r environment.txt`, then `pip install -e .` and
`jupyter lab notebooks/` in that folder (the README says which environment variables keep it quiet and fast).

When a page names a file, such as `helpers/slam/pipeline.py`, `docs/REFERENCE.md` or the README, it is a
file of that folder. The download button at the top of each page gives that page's notebook alone: it
imports the `helpers` package, so run it in the project's `notebooks/` folder. Each exercise checks your
answer in the notebook; the worked answers are in the appendix.
"""


def index_page(
    source: Path, chapters: list[Path], solutions: list[Path], picture: bool, archive: str, archive_bytes: int
) -> str:
    """The landing page's Markdown: introduction, result, goals, how to run (with a link to ``archive``, the
    project's zip beside the page, of ``archive_bytes``), a line per page, the toctrees."""
    lines = [f"# {TITLE}", "", INTRODUCTION]
    if picture:
        lines += [RESULT]
    link = f'<a href="{archive}" download>{archive}</a>'  # a file beside the page, not a page of the book
    lines += [GOALS, RUNNING.format(link=link, size=f" ({archive_bytes / 1e6:.0f} MB)"), "## The pages", ""]
    for path in chapters:
        lines.append(f"- [{page_title(source / path.name)}]({path.name}){SEPARATOR}{summary(path)}")
    if solutions:
        lines += ["", "## Appendix", ""]
        lines += [f"- [{page_title(source / SOLUTIONS / p.name)}]({SOLUTIONS}/{p.name})" for p in solutions]
    lines += ["", "```{toctree}", ":hidden:", ":caption: The tutorial", "", *[p.stem for p in chapters], "```"]
    if solutions:
        lines += ["", "```{toctree}", ":hidden:", ":caption: Appendix: solutions", ""]
        lines += [*[f"{SOLUTIONS}/{p.stem}" for p in solutions], "```"]
    return "\n".join(lines) + "\n"


def page_title(path: Path) -> str:
    """The notebook's first top-level heading."""
    import nbformat

    for cell in nbformat.read(path, as_version=4).cells:
        if cell.cell_type == "markdown":
            for line in cell.source.splitlines():
                if line.startswith("# "):
                    return line[2:].strip()
    return path.stem


def summary(path: Path) -> str:
    """What the page teaches: SUMMARIES, else the first sentence after its title."""
    if path.name[:2] in SUMMARIES:
        return SUMMARIES[path.name[:2]]
    import nbformat

    for cell in nbformat.read(path, as_version=4).cells:
        if cell.cell_type == "markdown":
            for paragraph in cell.source.split("\n\n"):
                if paragraph.strip() and not paragraph.lstrip().startswith("#"):
                    return re.split(r"(?<=[.!?])\s", " ".join(paragraph.split()), maxsplit=1)[0]
    return ""
