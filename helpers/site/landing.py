"""The book's landing page: what the reader will learn, what they need to know
first, how long it takes, how to run the notebooks themselves, and a line per
page saying what it teaches, linked, in reading order."""

from __future__ import annotations

import re
from pathlib import Path

TITLE = "Aerial lidar SLAM, step by step"
SOLUTIONS = "solutions"  # notebooks/solutions/*.ipynb: the book's appendix, and its folder in the book
RESULT_PICTURE = Path("figures") / "result.png"  # the landing page's picture (the README's)

# What each page teaches, one line on the landing page (by the notebook's number; a notebook not listed
# here gets the first sentence of its introduction).
SUMMARIES = {
    "01": (
        "the two input files the reference starts from; the map, the flight and the lidar's fan of rays; "
        "one scan cast by hand with Open3D; the footprint"
    ),
    "02": "what each parameter controls, a picture each, and which defaults are the reference's and which are ours",
    "03": (
        "one pair of scans through FPFH features, matching, Kabsch, MSAC and ICP, each step checked against the "
        "truth and beside the library call that does it; each parameter swept on the pair"
    ),
    "04": "odometry over the whole flight, its errors and drift, and tracking; then scans merged into submaps",
    "05": "recognising a place seen before; the reference's main loop written out and checked against the pipeline",
    "06": "one loop edge on a line, the same chain in GTSAM factor by factor, then our graph and a robust kernel",
    "07": "the rebuilt map scored against the truth, and the reference workflow against ours on the same flight",
    "08": (
        "a sparse tile flown low, where the reference's values lose the track; how sure each step is, drawn "
        "along the track; a motion factor and GNSS fixes added to the graph factor by factor"
    ),
}

INTRODUCTION = """\
A drone flies over an aerial map and scans the ground with a lidar. These pages rebuild, one stage a page,
the whole SLAM pipeline that turns those scans into a trajectory and a map: registration of scan pairs,
submaps, loop closure and a pose graph, each measured against the ground truth the simulator keeps.
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

## Running the notebooks yourself

These pages are the notebooks as they were last executed. To run them, change them and do the exercises:

1. clone the repository and, on Debian with Python 3.11, run `make setup` (it creates `.venv/` and installs
   the pinned packages), or in an environment of your own run `pip install -r environment.txt` then
   `pip install -e .` in the checkout;
2. start JupyterLab in the checkout (`.venv/bin/jupyter lab notebooks/` after `make setup`; the README says
   which environment variables keep it quiet and fast) and open the notebooks in order.

The download button at the top of each page gives that page's notebook, but it imports the `helpers`
package of the repository: run it inside a checkout (or with the package installed), not on its own.
Each exercise checks your answer in the notebook; the worked answers are in the appendix.
"""


def index_page(source: Path, chapters: list[Path], solutions: list[Path], picture: bool) -> str:
    """The landing page's Markdown: introduction, result, goals, how to run, a line per page, the toctrees."""
    lines = [f"# {TITLE}", "", INTRODUCTION]
    if picture:
        lines += [RESULT]
    lines += [GOALS, "## The pages", ""]
    for path in chapters:
        lines.append(f"- [{page_title(source / path.name)}]({path.name}): {summary(path)}")
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
