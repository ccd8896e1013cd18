"""The one place that decides how 3-D views are drawn.

No machine of this project has a display, so VTK renders off-screen with
OSMesa (Debian's ``libosmesa6``): :func:`use_offscreen_vtk` chooses it just
before :mod:`helpers.viz.render` first imports PyVista (importing ``helpers``
or ``helpers.viz`` sets nothing); that also keeps VTK from writing "bad X
server connection" into notebook outputs. Set ``VTK_DEFAULT_OPENGL_WINDOW``
yourself (e.g. ``vtkEGLRenderWindow``) to choose another back end.

A notebook kernel should start with :data:`KERNEL_ENVIRONMENT` (the site
builder and nbval start theirs so): Open3D's web visualiser, which needs a
browser connection and prints a banner in every notebook, is switched off
when Open3D is imported, which importing ``helpers.sim.dataset`` does. In
JupyterLab, start it so: ``OPEN3D_DISABLE_WEB_VISUALIZER=true jupyter lab``.

The big 3-D views of the notebooks (:func:`helpers.viz.render.explore`) are
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


# OMP_WAIT_POLICY: Open3D's and small_gicp's OpenMP threads otherwise spin after each parallel call and
# starve numpy's (registration 13 % slower on 2 cores); it must be set before Open3D loads.
KERNEL_ENVIRONMENT = {
    "OPEN3D_DISABLE_WEB_VISUALIZER": "true",
    "OMP_WAIT_POLICY": "passive",
    VIEW_MODE_VARIABLE: "static",
}


def use_offscreen_vtk() -> None:
    """Render VTK off-screen with OSMesa unless ``VTK_DEFAULT_OPENGL_WINDOW``
    says otherwise; called before PyVista is first imported."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkOSOpenGLRenderWindow")


def view_mode() -> str:
    """``HELPERS_3D``: ``auto`` (the default) or ``static``."""
    from helpers.errors import SlamError

    mode = os.environ.get(VIEW_MODE_VARIABLE, "auto").strip().lower() or "auto"
    if mode not in VIEW_MODES:
        raise SlamError(f"{VIEW_MODE_VARIABLE}={mode!r}: use one of {', '.join(VIEW_MODES)}")
    return mode


def interactive_views() -> bool:
    """Whether :func:`helpers.viz.render.explore` draws an interactive view: not
    when ``HELPERS_3D=static``; otherwise when this runs in a Jupyter kernel
    and PyVista's trame back end is installed."""
    if view_mode() == "static":
        return False
    return in_jupyter_kernel() and importlib.util.find_spec("trame_pyvista") is not None


def in_jupyter_kernel() -> bool:
    shell = sys.modules.get("IPython") and sys.modules["IPython"].get_ipython()
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})
