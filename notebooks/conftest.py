"""nbval compares the notebooks with their committed outputs, whose 3-D views
are still pictures: the kernels it starts from this process must draw them
as pictures too, whatever is installed (``pytest notebooks/NN.ipynb`` alone
included)."""

import os

from helpers.display import VIEW_MODE_VARIABLE

os.environ[VIEW_MODE_VARIABLE] = "static"
