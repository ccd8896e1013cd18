"""The one place that decides how 3-D views are drawn.

No machine of this project has a display, so VTK renders off-screen with
OSMesa (Debian's ``libosmesa6``), chosen before VTK is first imported; that
also keeps VTK from writing "bad X server connection" into notebook outputs.
Set ``VTK_DEFAULT_OPENGL_WINDOW`` yourself (e.g. ``vtkEGLRenderWindow``) to
choose another back end. Open3D's web visualiser (which needs a browser
connection and prints a banner in every notebook) is switched off too.

The big 3-D views of the notebooks (:func:`helpers.render.explore`) are
interactive when a person can use them: in a Jupyter kernel with PyVista's
trame back end installed (``trame-pyvista``, in ``environment.txt``), you can
turn, zoom and pan them in JupyterLab. Everywhere else, and whenever
``HELPERS_3D=static`` is set, they are still images, the same in JupyterLab,
in nbval and in the static HTML site (both set ``HELPERS_3D=static``, so the
notebooks' outputs stay pictures that a page opened from disk can show).
"""

import importlib.util
import os
import sys

VIEW_MODE_VARIABLE = "HELPERS_3D"
VIEW_MODES = ("auto", "static")


def select_offscreen_backend() -> None:
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkOSOpenGLRenderWindow")
    os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")
    # Open3D's OpenMP threads otherwise spin after each call and starve
    # numpy's (measured: 1.2 s instead of 0.35 s per registered scan).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def view_mode() -> str:
    """``HELPERS_3D``: ``auto`` (the default) or ``static``."""
    from .errors import SlamError

    mode = os.environ.get(VIEW_MODE_VARIABLE, "auto").strip().lower() or "auto"
    if mode not in VIEW_MODES:
        raise SlamError(f"{VIEW_MODE_VARIABLE}={mode!r}: use one of {', '.join(VIEW_MODES)}")
    return mode


def interactive_views() -> bool:
    """Whether :func:`helpers.render.explore` draws an interactive view: not
    when ``HELPERS_3D=static``; otherwise when this runs in a Jupyter kernel
    and PyVista's trame back end is installed."""
    if view_mode() == "static":
        return False
    return in_jupyter_kernel() and importlib.util.find_spec("trame_pyvista") is not None


def in_jupyter_kernel() -> bool:
    shell = sys.modules.get("IPython") and sys.modules["IPython"].get_ipython()
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})
