"""The look shared by every picture: one colour per thing in all seven
notebooks, the height and error colour maps, the size of a 3-D view, the grid,
and the sizes of figures and their type, so that no text of a picture is
under 11 px where the book shows it.

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

# The size of what a picture says. A figure is shown DPI CSS pixels to the inch (drawn at twice that, to stay
# sharp), so a type of TEXT_PT points is TEXT_PT * DPI / 72 pixels tall on the page, as long as the figure is
# no wider than the column that shows it: a wider one is shrunk to fit, its legends and ticks with it. The
# book's text column is BOOK_COLUMN_PX wide on a 1366 px laptop screen (729 px there, beside the two
# sidebars), so the widest figure, FIGURE_WIDTH, fits it whole; no text in a picture is then under
# MIN_TEXT_PX, against the page's 16 px text. A phone shows the figure smaller: a tap opens it alone, to zoom.
DPI = 80
BOOK_COLUMN_PX = 720
FIGURE_WIDTH = 8.9  # inches: 712 px, and a few more for the tight frame around it
MIN_TEXT_PX = 11
TEXT_PT = 10  # the smallest type: ticks, legends, notes (matplotlib's default size); titles are larger
SHARPNESS = 2  # a picture is drawn at this many pixels per CSS pixel it is shown at


def shown_text_px(points: float, width_px: float, shown_px: float | None = None) -> float:
    """How tall a type of ``points`` looks in a picture drawn ``width_px`` CSS pixels wide (at DPI) and
    shown ``shown_px`` wide (by default the book's column, or less if the picture is narrower)."""
    shown = min(width_px, BOOK_COLUMN_PX) if shown_px is None else shown_px
    return points * DPI / 72 * shown / width_px


def view_text_px(window_width: int, shown_px: float) -> int:
    """The type size (pixels) for the text of a 3-D view rendered ``window_width`` pixels wide and shown
    ``shown_px`` wide, so that it is MIN_TEXT_PX tall as shown."""
    return max(MIN_TEXT_PX, int(np.ceil(MIN_TEXT_PX * window_width / shown_px)))


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
