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


def test_a_3d_view_has_a_scale_with_round_ticks():
    assert render._round_ticks(-399.5, 399.5) == (-400.0, 400.0, 5)
    assert render._round_ticks(3.2, 7.9) == (3.0, 8.0, 6)
    first, last, n = render._round_ticks(-123.4, 567.8)
    step = (last - first) / (n - 1)
    assert first <= -123.4 and last >= 567.8 and n <= 7 and step in (100.0, 200.0, 500.0)
    points = np.random.default_rng(0).random((400, 3)) * [100, 80, 10]
    plain, scaled = (render.cloud_view(points, (300, 200), axes=axes) for axes in (False, True))
    assert plain.shape == scaled.shape and not np.array_equal(plain, scaled)


def test_no_colour_map_of_the_pictures_ends_near_white():
    import matplotlib

    for name in (render.HEIGHT_CMAP, render.ERROR_CMAP):
        top = np.asarray(matplotlib.colormaps[name](1.0)[:3])
        assert top.min() < 0.5, f"{name} ends near white: {top}"
