"""Draw the README's picture, notebooks/figures/result.png, from the default
run (computed once, then read from data/cache):

    .venv/bin/python notebooks/figures/readme_figure.py
"""

from pathlib import Path

import matplotlib.pyplot as plt

from helpers import default_run
from helpers.viz import figures

dataset, result = default_run()
fig = figures.trajectories_figure(
    dataset.poses[result.indices],
    result.poses_odometry,
    result.poses_optimized,
    zoom=None,
    title="the default flight: ground truth, odometry only, after loop closure and optimisation",
)
fig.savefig(Path(__file__).with_name("result.png"), dpi=80)
plt.close(fig)
