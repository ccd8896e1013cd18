"""nbval compares the notebooks with their committed outputs, whose 3-D views
are still pictures: the kernels it starts from this process must draw them
as pictures too, whatever is installed (``pytest notebooks/NN.ipynb`` alone
included), and Open3D must not announce its web visualiser in them."""

import os

from helpers.viz.display import KERNEL_ENVIRONMENT

os.environ.update(KERNEL_ENVIRONMENT)
