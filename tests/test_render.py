"""How the notebooks draw: 3-D views are interactive only in a live Jupyter
kernel with PyVista's trame back end, pictures everywhere else; the scan
player needs nothing from the network."""

import importlib.util
import os

import nbformat
import numpy as np
import pytest
from IPython.display import Image
from nbclient import NotebookClient

from helpers import SlamError
from helpers.viz import render
from helpers.viz.display import VIEW_MODE_VARIABLE, interactive_views, view_mode

WIDGET = "application/vnd.jupyter.widget-view+json"
IMPORTS = "import os\nimport numpy as np\nfrom helpers.viz import render"
CLOUD = "np.random.default_rng(0).random((400, 3)) * [100, 80, 10]"


def test_an_unknown_view_mode_is_one_clear_error(monkeypatch):
    monkeypatch.setenv(VIEW_MODE_VARIABLE, "3d")
    with pytest.raises(SlamError, match="HELPERS_3D='3d': use one of auto, static"):
        view_mode()


def test_outside_a_kernel_a_view_is_the_still_picture(monkeypatch):
    monkeypatch.setenv(VIEW_MODE_VARIABLE, "auto")
    assert not interactive_views()  # pytest is no Jupyter kernel
    points = np.random.default_rng(0).random((400, 3)) * [100, 80, 10]
    shown = render.explore(points, title="a cloud", window=(300, 200))
    assert isinstance(shown, Image) and shown.format == "jpeg"
    assert shown.data == render.encode(render.cloud_view(points, (300, 200), title="a cloud"))


@pytest.mark.skipif(importlib.util.find_spec("trame_pyvista") is None, reason="trame-pyvista is not installed")
def test_in_a_kernel_a_view_is_interactive_unless_static_is_asked(monkeypatch):
    """A real kernel, as JupyterLab starts one: the first view is a trame
    widget, the second, after HELPERS_3D=static, a JPEG picture."""
    monkeypatch.setenv(VIEW_MODE_VARIABLE, "auto")
    notebook = nbformat.v4.new_notebook()
    notebook.cells = [
        nbformat.v4.new_code_cell(f"{IMPORTS}\nrender.explore({CLOUD})"),
        nbformat.v4.new_code_cell(f"os.environ['{VIEW_MODE_VARIABLE}'] = 'static'\nrender.explore({CLOUD})"),
    ]
    NotebookClient(notebook, timeout=120, resources={"metadata": {"path": os.getcwd()}}).execute()
    interactive, static = ([o for o in cell.outputs if o.output_type == "execute_result"] for cell in notebook.cells)
    assert WIDGET in interactive[0].data, f"expected a widget, got {sorted(interactive[0].data)}"
    assert "iframe" in interactive[0].data["text/plain"]
    assert "image/jpeg" in static[0].data and WIDGET not in static[0].data


def test_the_scan_player_loads_no_icon_font():
    scans = [np.random.default_rng(k).normal(size=(500, 3)) * [20, 150, 5] for k in range(3)]
    html = render.scan_player(scans, range(3))
    assert "font-awesome" not in html and 'class="fa ' not in html
    for title, icon in (("Play", "\u25b6"), ("Pause", "\u2016"), ("Next frame", "\u25b7")):
        assert icon in html, f"the {title} button has no icon"
