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
from helpers.viz.style import CLASS_COLORS, COLORS, ERROR_CMAP, FIGURE_WIDTH, HEIGHT_CMAP, WINDOW  # noqa: F401 (notebooks use render.ERROR_CMAP)


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


def figure_image(fig, dpi: int = 80) -> np.ndarray:
    """Draw a matplotlib figure into an RGB array (and close it)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    from PIL import Image

    buffer.seek(0)
    return np.asarray(Image.open(buffer).convert("RGB"))


def show_figure(fig, fmt: str = "png", dpi: int = 80, sharpness: int = 2):
    """Display a matplotlib figure as a still image (and close it). PNG keeps
    lines and text sharp; pass ``fmt="jpeg"`` for figures full of raster.

    The image is drawn at ``sharpness`` times ``dpi`` and shown at the size
    ``dpi`` gives, so small text (legends, ticks) stays readable when a
    browser zooms or a book column shrinks the figure."""
    image = figure_image(fig, dpi * sharpness)
    return show(image, fmt, width=round(image.shape[1] / sharpness))


def cloud_view(points: np.ndarray, window=WINDOW, **view) -> np.ndarray:
    """Points drawn by :func:`draw_cloud` (``view`` are its arguments) as an
    off-screen 3-D view of ``window`` pixels; returns an RGB array."""
    plotter = draw_cloud(_plotter(window), points, **view)
    image = plotter.screenshot(return_img=True)
    plotter.close()
    return image


def explore(points: np.ndarray, window=WINDOW, **view):
    """The view of :func:`cloud_view`, to turn, zoom and pan in JupyterLab
    when :func:`helpers.viz.display.interactive_views` allows it; otherwise the
    same view as a still image."""
    if not interactive_views():
        return show(cloud_view(points, window, **view))
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
):
    """Add points (coloured by ``scalars``, by default their height) and an
    optional path to a PyVista ``plotter``, and place its camera ``elevation``
    degrees above the horizon and ``azimuth`` degrees from +x; returns it.

    ``extra`` is a sequence of ``(points, color)`` drawn as flat-coloured
    clouds. ``path_height`` draws the path at that height instead of its own
    (a drone at 700 m would sit far above a map at 100 m). ``axes`` draws
    the scale (x and y axes in metres along the edges of the cloud's box) and
    a small x-y-z triad in the corner that shows which way the view looks.
    """
    pv = pyvista()

    cloud = pv.PolyData(np.asarray(points, np.float32))
    cloud["value"] = points[:, 2] if scalars is None else scalars
    plotter.add_mesh(
        cloud,
        scalars="value",
        cmap=cmap,
        clim=clim,
        point_size=point_size,
        render_points_as_spheres=False,
        scalar_bar_args={"title": scalar_title, "color": "black", "vertical": True, "fmt": "%.3g"},
    )
    for extra_points, color in extra:
        plotter.add_mesh(pv.PolyData(np.asarray(extra_points, np.float32)), color=color, point_size=point_size)
    if path is not None and len(path) > 1:
        path = np.array(path, np.float64)
        if path_height is not None:
            path[:, 2] = path_height
        plotter.add_mesh(pv.lines_from_points(np.asarray(path, np.float32)), color=path_color, line_width=3)
        plotter.add_mesh(pv.PolyData(np.asarray(path[:1], np.float32)), color=path_color, point_size=12)
    if title:
        plotter.add_text(title, font_size=11, color="black")
    framed = points
    if axes:
        box = add_scale(plotter, points)
        framed = np.vstack([points[:, :3].min(axis=0), points[:, :3].max(axis=0), box])
        zoom = zoom / 1.08  # room for the tick labels
    _place_camera(plotter, framed, elevation, azimuth, zoom)
    return plotter


def add_scale(plotter, points: np.ndarray, font_size: int = 10) -> np.ndarray:
    """Axes with round ticks in metres along the x and y edges of a box just
    around the points (the heights are read from the colour bar), and a small
    x-y-z triad in the lower-left corner; returns the box's two corners (2, 3)."""
    lo, hi = np.min(points, axis=0), np.max(points, axis=0)
    (x0, x1, nx), (y0, y1, ny) = (_round_ticks(lo[k], hi[k]) for k in (0, 1))
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
    plotter.add_axes(color="black", line_width=2, viewport=(0.0, 0.0, 0.12, 0.18))
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
        fontsize=8,
    )
    for ax, title in ((left, "surface height"), (right, "what covers the ground")):
        ax.set(title=title, xlabel="x (m)", ylabel="y (m)")
        if waypoints is not None:
            ax.plot(waypoints[:, 0], waypoints[:, 1], color=COLORS["waypoints"], lw=1.5, label="flight")
            ax.plot(*waypoints[0, :2], "o", color=COLORS["waypoints"])
    return fig
