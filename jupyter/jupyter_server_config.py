"""The project's JupyterLab settings, read when the server starts with this folder on JUPYTER_CONFIG_PATH
(``make lab``, or the README's command); the user's own (~/.jupyter) still apply, and win where they set the same.

- conftest.py (nbval's, for make test) is left out of the notebooks' folder listing;
- the kernels inherit these variables, set before a notebook imports Open3D: OpenMP's threads sleep instead of
  spinning and starving numpy's (lower case: libgomp compares it in the user's locale), and Open3D keeps its
  web-visualiser notice out of every notebook.

labconfig/page_config.json beside this file turns off the "Build Recommended" check: dash, which Open3D
needs, installs a JupyterLab extension in source form that the notebooks never use.
"""

import os

c = get_config()  # noqa: F821 (the name Jupyter gives a config file)

c.ContentsManager.hide_globs = ["__pycache__", "*.pyc", "*.pyo", ".DS_Store", "*~", "conftest.py"]

os.environ.setdefault("OMP_WAIT_POLICY", "passive")
os.environ.setdefault("OPEN3D_DISABLE_WEB_VISUALIZER", "true")
