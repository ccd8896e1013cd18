"""What the book changes in its copy of a notebook before Sphinx reads it (the
checkout's notebooks are never touched), so that a notebook written for
JupyterLab reads the same in the book:

- a cell JupyterLab shows folded (``jupyter.source_hidden`` /
  ``outputs_hidden``) gets myst-nb's tag that folds the same parts;
- a figure cell (``mystnb.figure`` metadata) that also shows other outputs (a
  table, a value) is split so that only its picture becomes the numbered
  figure: myst-nb would wrap every output of the cell in a figure of the same
  name (two figures numbered, a duplicate label).
"""

from __future__ import annotations

import copy

# What a folded cell of JupyterLab becomes in the book: myst-nb's tag folding the same parts behind a toggle.
FOLD_TAGS = {(True, True): "hide-cell", (True, False): "hide-input", (False, True): "hide-output"}
BOOK_TAGS = {"hide-cell", "hide-input", "hide-output", "remove-cell", "remove-input", "remove-output"}
REST = "# the rest of the cell above"  # a split part's code, never shown (myst-nb drops a cell with none)
SHOWN = ("display_data", "execute_result")  # the outputs myst-nb wraps in a cell's figure (streams it does not)


def prepare(notebook) -> None:
    """Both changes, in place, on the book's copy."""
    fold_hidden_cells(notebook)
    split_figure_cells(notebook)


def fold_hidden_cells(notebook) -> None:
    """Tags each code cell JupyterLab shows folded and the book would not, so both fold it the same way."""
    for cell in notebook.cells:
        hidden = cell.metadata.get("jupyter", {})
        fold = FOLD_TAGS.get((bool(hidden.get("source_hidden")), bool(hidden.get("outputs_hidden"))))
        tags = cell.metadata.get("tags", [])
        if cell.cell_type == "code" and fold and not BOOK_TAGS.intersection(tags):
            cell.metadata["tags"] = [*tags, fold]


def _is_picture(output) -> bool:
    return output.output_type in SHOWN and any(kind.startswith("image/") for kind in output.get("data", {}))


def split_figure_cells(notebook) -> None:
    """A figure cell showing more than its picture becomes consecutive cells: the code with the outputs before
    the picture, the picture alone with the figure's metadata, then the outputs after it (the later ones
    without their code, so the page reads as before). Only the cell's first picture is the figure."""
    cells = []
    for cell in notebook.cells:
        figure = cell.metadata.get("mystnb", {}).get("figure") if cell.cell_type == "code" else None
        shown = [output for output in cell.get("outputs", []) if output.output_type in SHOWN]
        first = next((n for n, output in enumerate(cell.get("outputs", [])) if _is_picture(output)), None)
        if not figure or first is None or len(shown) == 1:
            cells.append(cell)
            continue
        plain = copy.deepcopy(cell.metadata)
        plain["mystnb"] = {key: value for key, value in plain["mystnb"].items() if key not in ("figure", "image")}
        outputs = cell.outputs
        parts = [(cell.source, plain, outputs[:first]), (REST, cell.metadata, outputs[first : first + 1])]
        parts.append((REST, plain, outputs[first + 1 :]))
        for number, (source, metadata, kept) in enumerate(parts):
            if number and not kept:
                continue
            part = copy.deepcopy(cell)
            part.source, part.metadata, part.outputs = source, copy.deepcopy(metadata), kept
            if number:
                part["id"] = f"{cell.get('id') or 'cell'}-{len(cells)}"  # unique: the place in the new list
                part.metadata["tags"] = [*part.metadata.get("tags", []), "remove-input"]
            cells.append(part)
    notebook.cells = cells
