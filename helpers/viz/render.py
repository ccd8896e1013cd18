"""Pictures for the notebooks: point clouds with PyVista (off-screen, fixed
camera) and trajectories with matplotlib, in the same colours everywhere.

Every function returns something a notebook displays as a still image (PNG
or JPEG bytes inside ``IPython.display.Image``) or an HTML animation, so the
pictures survive a static HTML export and need no running kernel. The one
exception is :func:`explore`, which in a live JupyterLab kernel with trame
returns an interactive view instead (decided by :mod:`helpers.viz.display`).
"""

from __future__ import annotations

import io

import matplotlib.pyplot as plt
import numpy as np

from helpers.sim.scene import CLASS_NAMES
from helpers.viz.display import interactive_views, use_offscreen_vtk
from helpers.viz.player import scan_player, top_down  # noqa: F401 (notebooks call render.scan_player)
from helpers.viz.style import (  # noqa: F401 (notebooks use render.ERROR_CMAP)
    BOOK_COLUMN_PX,
    CLASS_COLORS,
    COLORS,
    DPI,
    ERROR_CMAP,
    FIGURE_WIDTH,
    HEIGHT_CMAP,
    SHARPNESS,
    TEXT_PT,
    WINDOW,
    view_text_px,
)

PAIR_PX = BOOK_COLUMN_PX / 2  # how wide the book shows a view set beside another (notebook 7's maps)
TITLE_SCALE = 1.5  # a view's title against its smallest text


def pyvista():
    """PyVista, imported after :func:`helpers.viz.display.use_offscreen_vtk`."""
    use_offscreen_vtk()
    import pyvista as pv

    return pv


def _plotter(window=WINDOW):
    pv = pyvista()
    plotter = pv.Plotter(off_screen=True, window_size=list(window))
    plotter.set_background("white")
    return plotter


def encode(image: np.ndarray, fmt: str = "jpeg") -> bytes:
    """An RGB array as JPEG (the default: small, fine for maps and clouds) or PNG bytes."""
    from PIL import Image

    buffer = io.BytesIO()
    if fmt == "jpeg":
        Image.fromarray(image).save(buffer, format="JPEG", quality=88)
    else:
        Image.fromarray(image).save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def show(image: np.ndarray, fmt: str = "jpeg", width: int | None = None):
    """Display an RGB array in a notebook as a still image, ``width`` CSS pixels wide if given."""
    from IPython.display import Image

    return Image(data=encode(image, fmt), format=fmt, width=width)


def figure_image(fig, dpi: int = DPI) -> np.ndarray:
    """Draw a matplotlib figure into an RGB array (and close it)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    from PIL import Image

    buffer.seek(0)
    return np.asarray(Image.open(buffer).convert("RGB"))


def show_figure(fig, fmt: str = "png", dpi: int = DPI, sharpness: int = SHARPNESS):
    """Display a matplotlib figure as a still image (and close it). PNG keeps
    lines and text sharp; pass ``fmt="jpeg"`` for figures full of raster.

    The image is drawn at ``sharpness`` times ``dpi`` and shown at the size
    ``dpi`` gives (a figure ``style.FIGURE_WIDTH`` wide fills the book's
    column), so small text (legends, ticks) stays sharp when a browser zooms."""
    image = figure_image(fig, dpi * sharpness)
    return show(image, fmt, width=round(image.shape[1] / sharpness))


def cloud_view(points: np.ndarray, window=WINDOW, shown_px: float = PAIR_PX, **view) -> np.ndarray:
    """Points drawn by :func:`draw_cloud` (``view`` are its arguments) as an
    off-screen 3-D view of ``window`` pixels; returns an RGB array. Its text is
    sized to be read when the view is shown ``shown_px`` wide: by default half
    the book's column, as a view set beside another (``np.hstack``) is shown."""
    view.setdefault("text_px", view_text_px(window[0], shown_px))
    plotter = draw_cloud(_plotter(window), points, **view)
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return image


def explore(points: np.ndarray, window=WINDOW, **view):
    """The view of :func:`cloud_view`, to turn, zoom and pan in JupyterLab
    when :func:`helpers.viz.display.interactive_views` allows it; otherwise the
    same view as a still image."""
    if not interactive_views():  # shown alone: as wide as drawn, or the book's column
        return show(cloud_view(points, window, min(window[0], BOOK_COLUMN_PX), **view))
    pv = pyvista()

    plotter = pv.Plotter(notebook=True, window_size=list(window))
    plotter.set_background("white")
    return draw_cloud(plotter, points, **view).show(jupyter_backend="trame", return_viewer=True)


def draw_cloud(
    plotter,
    points: np.ndarray,
    scalars: np.ndarray | None = None,
    cmap: str = HEIGHT_CMAP,
    clim=None,
    point_size: float = 2.0,
    path: np.ndarray | None = None,
    path_color: str = COLORS["waypoints"],
    path_height: float | None = None,
    title: str | None = None,
    elevation: float = 55.0,
    azimuth: float = -60.0,
    zoom: float = 1.3,
    scalar_title: str = "height (m)",
    extra=(),
    axes: bool = True,
    text_px: int | None = None,
):
    """Add points (coloured by ``scalars``, by default their height) and an
    optional path to a PyVista ``plotter``, and place its camera ``elevation``
    degrees above the horizon and ``azimuth`` degrees from +x; returns it.

    ``extra`` is a sequence of ``(points, color)`` drawn as flat-coloured
    clouds. ``path_height`` draws the path at that height instead of its own
    (a drone at 700 m would sit far above a map at 100 m). ``axes`` draws
    the scale (x and y axes in metres along the edges of the cloud's box) and
    a small x-y-z triad in the corner that shows which way the view looks.
    ``text_px``: the size of its smallest text (ticks, colour bar, triad), in
    the view's pixels; the title is larger. By default it is 11 px when the
    view is shown alone, as wide as drawn or the book's column.
    """
    pv = pyvista()
    if text_px is None:
        width = plotter.window_size[0]
        text_px = view_text_px(width, min(width, BOOK_COLUMN_PX))
    bar = _colour_bar_place(plotter.window_size, text_px)

    cloud = pv.PolyData(np.asarray(points, np.float32))
    cloud["value"] = points[:, 2] if scalars is None else scalars
    plotter.add_mesh(
        cloud,
        scalars="value",
        cmap=cmap,
        clim=clim,
        point_size=point_size,
        render_points_as_spheres=False,
        scalar_bar_args={
            "title": scalar_title,
            "color": "black",
            "vertical": True,
            "fmt": "%.3g",
            "title_font_size": text_px,
            "label_font_size": text_px,
            **bar,
        },
    )
    for extra_points, color in extra:
        plotter.add_mesh(pv.PolyData(np.asarray(extra_points, np.float32)), color=color, point_size=point_size)
    if path is not None and len(path) > 1:
        path = np.array(path, np.float64)
        if path_height is not None:
            path[:, 2] = path_height
        plotter.add_mesh(pv.lines_from_points(np.asarray(path, np.float32)), color=path_color, line_width=3)
        plotter.add_mesh(pv.PolyData(np.asarray(path[:1], np.float32)), color=path_color, point_size=12)
    if title:  # PyVista doubles a title's size: font_size 11 is 22 pixels
        plotter.add_text(title, font_size=round(TITLE_SCALE * text_px / 2), color="black")
    framed = points
    if axes:
        box = add_scale(plotter, points, text_px)
        framed = np.vstack([points[:, :3].min(axis=0), points[:, :3].max(axis=0), box])
        zoom = zoom / (1.0 + 4.0 * text_px / plotter.window_size[0])  # room for the tick labels
    # The cloud keeps to the left of the colour bar: framed smaller, its centre moved left by half the bar's
    # room, and up by the height of a tick label, whose labels hang below the box's front corner.
    room = 1.0 - bar["position_x"]
    _place_camera(plotter, framed, elevation, azimuth, zoom * (1.0 - room))
    plotter.camera.SetWindowCenter(room, -2.0 * text_px / plotter.window_size[1] if axes else 0.0)
    return plotter


def add_scale(plotter, points: np.ndarray, font_size: int = 14) -> np.ndarray:
    """Axes with round ticks in metres along the x and y edges of a box just
    around the points (the heights are read from the colour bar), and a small
    x-y-z triad in the lower-left corner, all their text ``font_size`` pixels;
    returns the box's two corners (2, 3)."""
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    width, height = plotter.window_size
    most = int(np.clip(width / (7 * font_size), 5, 7))  # fewer ticks when their labels are large in the view
    (x0, x1, nx), (y0, y1, ny) = (_round_ticks(lo[k], hi[k], most) for k in (0, 1))
    plotter.show_bounds(
        bounds=(x0, x1, y0, y1, lo[2], lo[2]),
        show_zaxis=False,
        show_zlabels=False,
        location="front",
        ticks="outside",
        xtitle="x (m)",
        ytitle="y (m)",
        n_xlabels=nx,
        n_ylabels=ny,
        fmt="%.0f",
        color="black",
        font_size=font_size,
        use_3d_text=False,
    )
    # The triad sits in the upper left, under the title, where the cloud's box (seen from its front corner)
    # leaves room; the tick labels run along the lower edges.
    side = max(0.12 * width, 6.0 * font_size)  # pixels: room for its three letters apart
    top = 1.0 - TITLE_SCALE * font_size * 1.6 / height
    viewport = (0.0, max(0.0, top - side / height), side / width, top)
    triad = plotter.add_axes(color="black", line_width=2, viewport=viewport)
    for caption in (triad.GetXAxisCaptionActor2D(), triad.GetYAxisCaptionActor2D(), triad.GetZAxisCaptionActor2D()):
        caption.GetTextActor().SetTextScaleModeToNone()  # VTK would fit the letter to the triad: a few pixels
        caption.GetCaptionTextProperty().SetFontSize(font_size)
    return np.array([[x0, y0, lo[2]], [x1, y1, lo[2]]])


def _round_ticks(lo: float, hi: float, most: int = 7) -> tuple[float, float, int]:
    """A range just around ``lo..hi`` whose ends are multiples of a round step
    (1, 2 or 5 times a power of ten) and its number of ticks, at most ``most``."""
    span = max(hi - lo, 1e-9)
    for step in (m * 10.0**e for e in range(int(np.floor(np.log10(span))) - 1, 12) for m in (1, 2, 5)):
        first, last = np.floor(lo / step) * step, np.ceil(hi / step) * step
        if (last - first) / step + 1 <= most:
            return float(first), float(last), round((last - first) / step) + 1
    return float(lo), float(hi), 2


def _colour_bar_place(window, text_px: int) -> dict:
    """Where a vertical colour bar sits so that its labels (up to six characters of ``text_px`` pixels) fit
    inside the window's right edge: PyVista's arguments position_x, position_y, width and height."""
    label = 6 * 0.6 * text_px / window[0]  # window fractions
    return {"position_x": 1.0 - 0.035 - label - 0.01, "position_y": 0.12, "width": 0.035, "height": 0.66}


def _place_camera(plotter, points, elevation, azimuth, zoom):
    """Look at the cloud's centre from ``elevation`` degrees above the horizon
    and ``azimuth`` degrees from the +x axis, z up."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    focal = (lo + hi) / 2
    distance = 1.9 * np.linalg.norm(hi - lo) / zoom
    el, az = np.radians(elevation), np.radians(azimuth)
    direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    plotter.camera_position = [tuple(focal + distance * direction), tuple(focal), (0.0, 0.0, 1.0)]


def thin(points: np.ndarray, every: int, *arrays):
    """Every ``every``-th point (and the same rows of ``arrays``): a fixed,
    seedless thinning for drawing large clouds quickly."""
    keep = slice(None, None, max(1, every))
    return (points[keep], *(a[keep] for a in arrays)) if arrays else points[keep]


def height_field_figure(field, waypoints: np.ndarray | None = None):
    """Two maps of the scene seen from above: heights and classes."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    xmin, xmax, ymin, ymax = field.bounds
    extent = (xmin, xmax, ymin, ymax)
    fig, (left, right) = plt.subplots(1, 2, figsize=(FIGURE_WIDTH, 3.8), constrained_layout=True)
    shown = np.where(field.valid, field.z, np.nan)
    im = left.imshow(shown, origin="lower", extent=extent, cmap=HEIGHT_CMAP)
    fig.colorbar(im, ax=left, label="height (m)", shrink=0.85)
    right.imshow(field.labels, origin="lower", extent=extent, cmap=ListedColormap(CLASS_COLORS), vmin=0, vmax=4)
    right.legend(
        handles=[Patch(color=c, label=n) for c, n in zip(CLASS_COLORS, CLASS_NAMES, strict=True)],
        loc="upper right",
        fontsize=TEXT_PT,
    )
    for ax, title in ((left, "surface height"), (right, "what covers the ground")):
        ax.set(title=title, xlabel="x (m)", ylabel="y (m)")
        if waypoints is not None:
            ax.plot(waypoints[:, 0], waypoints[:, 1], color=COLORS["waypoints"], lw=1.5, label="flight")
            ax.plot(*waypoints[0, :2], "o", color=COLORS["waypoints"])
    return fig
