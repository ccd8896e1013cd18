"""Draw the README's picture, notebooks/figures/result.png, from the default
run (computed once, then read from data/cache):

    .venv/bin/python notebooks/figures/readme_figure.py
"""

from pathlib import Path

import matplotlib.pyplot as plt

from helpers.viz import figures
from helpers.slam.pipeline import default_run

_, result = default_run()
start = result.poses_gt[0, :2, 3]
fig = figures.trajectories_figure(
    result.poses_gt,
    result.poses_odometry,
    result.poses_optimized,
    inset=(start[0] - 40, start[0] + 40, start[1] - 7, start[1] + 7),  # where the end of the flight meets its start
    title="the default flight: ground truth, odometry only, after loop closure and optimisation",
)
fig.savefig(Path(__file__).with_name("result.png"), dpi=80)
plt.close(fig)
