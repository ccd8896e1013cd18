"""A live view of :meth:`helpers.Slam.process`: the reference's loop shows
its pose graph growing at every scan (``show(pGraph)`` inside the loop);
this is the same idea for a notebook.

:class:`LiveView` records one frame per accepted scan (the odometry
trajectory so far, the scan's points in the map frame, the loop edges
closed so far) and, in a running notebook, redraws a top view in place
every few scans through one ``display`` handle. The same frames then make a
small HTML animation that plays offline, for the book::

    live = LiveView(dataset.poses)
    for index, scan in enumerate(dataset.scans):
        live.update(slam.process(scan, index), scan)
    live.finish()
    HTML(live.animation())
"""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np

from helpers.geometry import transform_points
from helpers.viz.player import FRAME_DPI, embedded_frames, offline_player
from helpers.viz.style import COLORS, DPI, FIGURE_WIDTH, GREY, TEXT_PT, grid, xy_of


@dataclass(frozen=True)
class Frame:
    """What the view showed after one accepted scan."""

    node: int  # the scan's pose-graph node
    index: int  # its dataset index
    trajectory: np.ndarray  # (node + 1, 2) odometry positions of nodes 0 .. node
    scan: np.ndarray  # (S, 2) a sample of the scan's points, map frame
    loops: tuple[tuple[int, int], ...]  # (i, j) of every loop edge closed up to this scan


class LiveView:
    """Record :class:`helpers.slam.slam.Step` after :class:`helpers.slam.slam.Step` and
    show them as a top view that updates in place.

    ``truth``: (N, 4, 4) or (N, 2+) true poses of the flight, drawn faint.
    ``every``: redraw after this many accepted scans (each redraw renders a
    figure, so every scan would slow the loop down). ``show``: False to only
    record (tests, scripts). ``sample``: points kept per scan. The left
    panel shows the whole flight, the right one ``zoom`` metres around the
    drone, where loop edges a few metres long can be seen."""

    def __init__(
        self, truth, every: int = 10, show: bool = True, sample: int = 400, size=(FIGURE_WIDTH, 3.9), zoom: float = 45.0
    ) -> None:
        self.truth = xy_of(truth)
        self.every, self.show, self.sample, self.size = max(1, int(every)), show, int(sample), size
        self.zoom = float(zoom)  # half-width (m) of the right panel, centred on the drone
        self.frames: list[Frame] = []
        self.handle = None
        self._positions: list[np.ndarray] = []
        self._loops: list[tuple[int, int]] = []

    def update(self, step, scan: np.ndarray | None = None) -> None:
        """Record ``step`` (what ``Slam.process`` returned) and its ``scan``
        (sensor frame); skipped scans are ignored. Redraws every ``every`` frames."""
        if not step.accepted:
            return
        self._positions.append(np.asarray(step.T_map_sensor, float)[:2, 3])
        if step.loop is not None:
            self._loops.append((int(step.loop.i), int(step.loop.j)))
        points = np.empty((0, 2))
        if scan is not None and len(scan):
            keep = np.linspace(0, len(scan) - 1, min(self.sample, len(scan))).astype(int)
            points = transform_points(np.asarray(scan, float)[keep], step.T_map_sensor)[:, :2]
        self.frames.append(Frame(step.node, step.index, np.array(self._positions), points, tuple(self._loops)))
        if self.show and len(self.frames) % self.every == 1:
            self._redraw()

    def finish(self) -> None:
        """Draw the last frame (the loop may end between two redraws)."""
        if self.show and self.frames:
            self._redraw()

    def figure(self, frame: Frame | None = None):
        """The top view after ``frame`` (the last one by default), as a matplotlib figure."""
        fig, axes = plt.subplots(1, 2, figsize=self.size, constrained_layout=True, width_ratios=[1.6, 1])
        artists = self._axes(axes)
        self._draw(artists, frame or self.frames[-1])
        return fig

    def animation(self, frames: int = 15, interval_ms: int = 300, dpi: int = FRAME_DPI, quality: int = 50) -> str:
        """The recorded frames as an HTML animation (play, pause, step) with
        its pictures embedded and nothing fetched from the network. At most
        ``frames`` pictures, spread over the run and always ending on the last
        frame, as JPEG of ``quality`` (lines and text survive a low one, and
        the page stays light) drawn at ``dpi``, shown at the figures' size."""
        from matplotlib import animation

        if not self.frames:
            raise ValueError("no frame recorded: call update() with what Slam.process returned first")
        picked = np.unique(np.linspace(0, len(self.frames) - 1, min(frames, len(self.frames))).round().astype(int))
        fig, axes = plt.subplots(1, 2, figsize=self.size, width_ratios=[1.6, 1])
        fig.subplots_adjust(left=0.09, right=0.98, bottom=0.25, top=0.9, wspace=0.25)  # no layout engine per frame
        artists = self._axes(axes)
        anim = animation.FuncAnimation(
            fig, lambda k: self._draw(artists, self.frames[picked[k]]), frames=len(picked), interval=interval_ms
        )
        html = embedded_frames(anim, interval_ms, "once", dpi, quality)
        plt.close(fig)
        return offline_player(html, round(self.size[0] * DPI))

    def _redraw(self) -> None:
        from IPython.display import display

        from helpers.viz.render import show_figure

        image = show_figure(self.figure())
        if self.handle is None:
            self.handle = display(image, display_id=True)
        else:
            self.handle.update(image)

    def _axes(self, axes) -> dict:
        """The parts every frame shares (the truth, the limits) and the artists a frame changes, per panel."""
        from matplotlib.collections import LineCollection
        from matplotlib.patches import Rectangle

        lo, hi = self.truth.min(axis=0), self.truth.max(axis=0)
        pad = 0.08 * (hi - lo).max()
        panels = []
        for ax in axes:
            ax.plot(*self.truth.T, color=COLORS["ground_truth"], lw=4, alpha=0.25, label="ground truth")
            (path,) = ax.plot([], [], color=COLORS["odometry"], lw=1.8, label="odometry so far")
            scan = ax.scatter([], [], s=1.5, color=GREY, label="current scan")
            (here,) = ax.plot([], [], "o", color=COLORS["odometry"], ms=6, mec="black", mew=0.6)
            loops = LineCollection([], colors=COLORS["loop"], lw=2.5, label="loop edges")
            ax.add_collection(loops)
            ax.set(aspect="equal", xlabel="x (m)")
            grid(ax)
            panels.append({"path": path, "scan": scan, "here": here, "loops": loops, "ax": ax})
        overview, zoom = axes
        overview.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad), ylabel="y (m)")
        window = Rectangle((0, 0), 2 * self.zoom, 2 * self.zoom, fill=False, color="black", lw=1)
        overview.add_patch(window)
        # Under both panels: under the left one alone, its four entries would not fit in the type they need.
        figure = overview.figure
        where = "outside lower center" if figure.get_layout_engine() else "lower center"
        figure.legend(*overview.get_legend_handles_labels(), loc=where, ncol=4, fontsize=TEXT_PT, markerscale=4)
        zoom.set_title(f"around the drone (\u00b1{self.zoom:.0f} m)", fontsize=10)
        title = overview.set_title("", fontsize=10)
        return {"panels": panels, "window": window, "title": title}

    def _draw(self, artists: dict, frame: Frame):
        path = frame.trajectory
        pairs = np.array(frame.loops, int).reshape(-1, 2)
        edges = [_arc(path[i], path[j]) for i, j in pairs]
        for panel in artists["panels"]:
            panel["path"].set_data(path[:, 0], path[:, 1])
            panel["here"].set_data(path[-1:, 0], path[-1:, 1])
            panel["scan"].set_offsets(frame.scan if len(frame.scan) else np.empty((0, 2)))
            panel["loops"].set_segments(edges)
        x, y = path[-1]
        zoom = artists["panels"][1]["ax"]
        zoom.set(xlim=(x - self.zoom, x + self.zoom), ylim=(y - self.zoom, y + self.zoom))
        artists["window"].set_xy((x - self.zoom, y - self.zoom))
        n = len(frame.loops)
        artists["title"].set_text(f"scan {frame.index}, node {frame.node}: {n} loop edge{'' if n == 1 else 's'} so far")
        return [artists["title"], artists["window"]] + [a for p in artists["panels"] for a in p.values()]


def _arc(a, b, bulge: float = 0.15, n: int = 12) -> np.ndarray:
    """(n, 2) points of a curve from ``a`` to ``b`` bowed to one side by
    ``bulge`` times their distance: a loop edge joins two nodes on the same
    track, and a straight segment would hide under the trajectory."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    side = np.array([-(b - a)[1], (b - a)[0]])  # a quarter turn left of a -> b
    t = np.linspace(0.0, 1.0, n)[:, None]
    return a + t * (b - a) + 4 * t * (1 - t) * bulge * side
