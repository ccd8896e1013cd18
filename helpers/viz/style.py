"""The look shared by every picture: one colour per thing in all seven
notebooks, the height and error colour maps, the size of a 3-D view, the grid.

Both colour maps are perceptually uniform and end in a saturated colour, not
near white: on the white background of the 3-D views a near-white top made
the tallest roofs (or the largest errors) look like holes in the map.
"""

from __future__ import annotations

import numpy as np

# One colour per thing, in all seven notebooks.
COLORS = {
    "ground_truth": "#2ca02c",  # green
    "odometry": "#d62728",  # red
    "optimized": "#1f77b4",  # blue
    "loop": "#ff7f0e",  # orange
    "waypoints": "#e41a1c",
    "moving": "#e377c2",  # the scan being registered
    "fixed": "#17becf",  # the scan it is registered to
    "reference": "#9467bd",  # purple: the reference workflow's run, beside ours (notebook 7)
}
CLASS_COLORS = ("#b9a77c", "#6b6b6b", "#3a7dc9", "#c1440e", "#2f7d32")  # by helpers.sim.scene label
HEIGHT_CMAP = "viridis"  # heights: dark violet (low) to yellow (high)
ERROR_CMAP = "plasma"  # errors and distances: dark blue (small) to yellow (large)
WINDOW = (900, 600)  # pixels of a 3-D view
# inches: the widest figure, 800 px at the notebooks' 80 dpi, about the book's column; a wider one is shrunk
# to fit and its legends and ticks with it
FIGURE_WIDTH = 10.0
GREY = "#9a9a9a"  # what is there but not the point (too recent submaps, ...)
LIGHT = "#d9d9d9"


def grid(ax, color: str = "#e6e6e6", open_frame: bool = False) -> None:
    """A light grid behind the data (and no top and right spines with ``open_frame``)."""
    ax.grid(True, color=color, lw=0.8)
    ax.set_axisbelow(True)
    if open_frame:
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)


def xy_of(trajectory) -> np.ndarray:
    """(N, 2) positions from (N, 4, 4) poses or (N, 2+) positions."""
    trajectory = np.asarray(trajectory, dtype=float)
    return trajectory[:, :2, 3] if trajectory.ndim == 3 else trajectory[:, :2]


def inset_zoom(ax, draw, window, at) -> None:
    """A zoom on ``window`` = (xmin, xmax, ymin, ymax) of a top view, drawn by
    ``draw(axis)`` into an inset at ``at`` (x0, y0, width, height in axes
    fractions), its frame marked on ``ax``."""
    zoom = ax.inset_axes(list(at))
    draw(zoom)
    zoom.set(xlim=window[:2], ylim=window[2:], aspect="equal", xticks=[], yticks=[])
    ax.indicate_inset_zoom(zoom, edgecolor="black")


def segments(a, b) -> np.ndarray:
    """(L, 2, 2) top-view segments from two (L, 2+) arrays of end points."""
    return np.stack([np.asarray(a)[:, :2], np.asarray(b)[:, :2]], axis=1)


def scale_bar(axis, width_m: float, where: str = "lower left") -> None:
    """A bar of a round length (1, 2 or 5 times a power of ten metres, about a quarter of
    ``width_m``, the width of the view) with its length written under it, so that a view
    without ticks still shows its scale."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    power = 10 ** np.floor(np.log10(width_m / 4))
    length = max(m * power for m in (1, 2, 5) if m * power <= width_m / 3)
    bar = AnchoredSizeBar(axis.transData, length, f"{length:g} m", where, frameon=False, size_vertical=0, pad=0.4)
    bar.size_bar.get_children()[0].set(linewidth=2.5)
    axis.add_artist(bar)
