"""The one place that decides how 3-D views are drawn.

No machine of this project has a display, so VTK renders off-screen with
OSMesa (Debian's ``libosmesa6``), chosen before VTK is first imported; that
also keeps VTK from writing "bad X server connection" into notebook outputs.
Set ``VTK_DEFAULT_OPENGL_WINDOW`` yourself (e.g. ``vtkEGLRenderWindow``) to
choose another back end. Open3D's web visualiser (which needs a browser
connection and prints a banner in every notebook) is switched off too.
"""

import os


def select_offscreen_backend() -> None:
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkOSOpenGLRenderWindow")
    os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")
    # Open3D's OpenMP threads otherwise spin after each call and starve
    # numpy's (measured: 1.2 s instead of 0.35 s per registered scan).
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
