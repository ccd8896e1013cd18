"""What the notebooks' text and layout promise, read from the committed
notebooks without running them: every check is folded away (JupyterLab and
the book show its toggle, not its lines of ``True``), a check is a cell of its
own (work never hides in a folded check, and no check shows in a work cell),
no markdown claims that ``Config.reference()`` is MATLAB's workflow exactly,
notebook 2 maps every parameter of the reference to its key here, and every
MATLAB call of the reference workflow is named where a notebook replaces it."""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest

from helpers.config import Config, describe

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
ALL = sorted(NOTEBOOKS.glob("0*.ipynb")) + sorted((NOTEBOOKS / "solutions").glob("*.ipynb"))
CHECK = "# Check:"
# Claims the outputs contradict (issue 62): our stages are our own code, and the loop thresholds run on our score.
EXACT_CLAIMS = (
    r"reference(?:'s)? workflow exactly",
    r"exactly the reference",
    r"exactly what the reference does",
    r"is the reference(?:'s)? workflow\b",
)
# The reference's calls (the SPEC's table), each named in the markdown of the notebooks that replace it.
MATLAB_CALLS = (
    "helperCreateDataset",
    "pcshow",
    "pcplayer",
    "pcdownsample",
    "extractFPFHFeatures",
    "pcmatchfeatures",
    "estgeotform3d",
    "pcregistericp",
    "pcalign",
    "helperEstimateLoopCandidates",
    "poseGraph3D",
    "addRelativePose",
    "optimizePoseGraph",
)


def _cells(path: Path, kind: str):
    return [(i, cell) for i, cell in enumerate(nbformat.read(path, as_version=4).cells) if cell.cell_type == kind]


def _name(path: Path, index: int) -> str:
    return f"{path.relative_to(NOTEBOOKS)} cell {index}"


def test_there_are_notebooks_and_checks():
    assert len(ALL) == 16, [p.name for p in ALL]
    checks = [i for path in ALL for i, cell in _cells(path, "code") if cell.source.startswith(CHECK)]
    assert len(checks) > 60


@pytest.mark.parametrize("path", ALL, ids=lambda p: p.stem)
def test_every_check_is_folded(path):
    """A cell that starts with '# Check:' is folded, its source and its output, in JupyterLab
    (``jupyter.source_hidden``, ``outputs_hidden``) and in the book (the ``hide-cell`` tag)."""
    unfolded = []
    for i, cell in _cells(path, "code"):
        if cell.source.startswith(CHECK):
            hidden = cell.metadata.get("jupyter", {})
            folded = hidden.get("source_hidden") and hidden.get("outputs_hidden")
            if not (folded and "hide-cell" in cell.metadata.get("tags", [])):
                unfolded.append(_name(path, i))
    assert not unfolded, f"checks in view: {unfolded}"


@pytest.mark.parametrize("path", ALL, ids=lambda p: p.stem)
def test_a_check_is_a_cell_of_its_own(path):
    """'# Check:' opens a cell or does not appear: a check after work in the same cell would either fold
    the work away with it or stay in view."""
    mixed = [
        _name(path, i)
        for i, cell in _cells(path, "code")
        if any(line.startswith(CHECK) for line in cell.source.splitlines()[1:]) and not cell.source.startswith(CHECK)
    ]
    assert not mixed, f"cells that do work, then check: {mixed}"


@pytest.mark.parametrize("path", ALL, ids=lambda p: p.stem)
def test_no_markdown_claims_the_reference_exactly(path):
    claims = [
        f"{_name(path, i)}: {match.group(0)!r}"
        for i, cell in _cells(path, "markdown")
        for pattern in EXACT_CLAIMS
        for match in re.finditer(pattern, cell.source, re.IGNORECASE)
    ]
    assert not claims, claims


def test_notebook_2_maps_every_reference_parameter_to_its_key():
    """A markdown table row (in plain view, not a folded output) names each parameter the reference has,
    its key here as `[table] key`, and the sections that teach it."""
    rows = [
        line
        for _, cell in _cells(NOTEBOOKS / "02_parameters.ipynb", "markdown")
        for line in cell.source.splitlines()
        if line.startswith("| `")
    ]
    config = Config()
    named = [
        (table, key, reference)
        for table in ("features", "registration", "map", "loop_closure", "pose_graph")
        for key, _, _, reference in describe(getattr(config, table))
        if reference is not None
    ]
    assert len(named) >= 15
    for table, key, reference in named:
        row = [line for line in rows if re.match(rf"\| `{reference}\b", line)]
        assert len(row) == 1, f"no single row for the reference's {reference}: {row}"
        assert f"`[{table}] {key}`" in row[0], row[0]
        assert re.search(r"\| \d\.\d+(?:\.\d+)?[^|]* \|$", row[0]), f"the row of {reference} names no section: {row[0]}"


def test_every_matlab_call_is_named_where_a_notebook_replaces_it():
    prose = "\n".join(cell.source for path in ALL[:8] for _, cell in _cells(path, "markdown"))
    missing = [call for call in MATLAB_CALLS if not re.search(rf"`{call}\b", prose)]
    assert not missing, missing
