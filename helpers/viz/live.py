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

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from ..geometry import transform_points
from .player import offline_player
from .style import COLORS, GREY, grid, segments, xy_of


@dataclass(frozen=True)
class Frame:
    """What the view showed after one accepted scan."""

    node: int  # the scan's pose-graph node
    index: int  # its dataset index
    trajectory: np.ndarray  # (node + 1, 2) odometry positions of nodes 0 .. node
    scan: np.ndarray  # (S, 2) a sample of the scan's points, map frame
    loops: tuple[tuple[int, int], ...]  # (i, j) of every loop edge closed up to this scan


class LiveView:
    """Record :class:`helpers.slam.Step` after :class:`helpers.slam.Step` and
    show them as a top view that updates in place.

    ``truth``: (N, 4, 4) or (N, 2+) true poses of the flight, drawn faint.
    ``every``: redraw after this many accepted scans (each redraw renders a
    figure, so every scan would slow the loop down). ``show``: False to only
    record (tests, scripts). ``sample``: points kept per scan."""

    def __init__(self, truth, every: int = 10, show: bool = True, sample: int = 400, size=(6.4, 5.2)) -> None:
        self.truth = xy_of(truth)
        self.every, self.show, self.sample, self.size = max(1, int(every)), show, int(sample), size
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
        fig, ax = plt.subplots(figsize=self.size, constrained_layout=True)
        artists = self._axes(ax)
        self._draw(artists, frame or self.frames[-1])
        return fig

    def animation(self, frames: int = 30, interval_ms: int = 250, dpi: int = 60) -> str:
        """The recorded frames as an HTML animation (play, pause, step) with
        its pictures embedded and nothing fetched from the network. At most
        ``frames`` pictures, spread over the run and always ending on the last
        frame; JPEG at ``dpi`` keeps the page light."""
        from matplotlib import animation

        if not self.frames:
            raise ValueError("no frame recorded: call update() with what Slam.process returned first")
        picked = np.unique(np.linspace(0, len(self.frames) - 1, min(frames, len(self.frames))).round().astype(int))
        fig, ax = plt.subplots(figsize=self.size)
        fig.subplots_adjust(left=0.12, right=0.97, bottom=0.1, top=0.93)  # fixed: no layout engine per frame
        artists = self._axes(ax)
        anim = animation.FuncAnimation(
            fig, lambda k: self._draw(artists, self.frames[picked[k]]), frames=len(picked), interval=interval_ms
        )
        with matplotlib.rc_context({"animation.frame_format": "jpeg", "savefig.dpi": dpi}):
            html = anim.to_jshtml(default_mode="once")
        plt.close(fig)
        return offline_player(html)

    def _redraw(self) -> None:
        from IPython.display import display

        from .render import show_figure

        image = show_figure(self.figure())
        if self.handle is None:
            self.handle = display(image, display_id=True)
        else:
            self.handle.update(image)

    def _axes(self, ax) -> dict:
        """The parts every frame shares (the truth, the limits) and the artists a frame changes."""
        lo, hi = self.truth.min(axis=0), self.truth.max(axis=0)
        pad = 0.08 * (hi - lo).max()
        ax.plot(*self.truth.T, color=COLORS["ground_truth"], lw=4, alpha=0.25, label="ground truth")
        (path,) = ax.plot([], [], color=COLORS["odometry"], lw=1.8, label="odometry so far")
        scan = ax.scatter([], [], s=1.5, color=GREY, label="current scan")
        (here,) = ax.plot([], [], "o", color=COLORS["odometry"], ms=6, mec="black", mew=0.6)
        from matplotlib.collections import LineCollection

        loops = LineCollection([], colors=COLORS["loop"], lw=2.5, label="loop edges")
        ax.add_collection(loops)
        ax.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad), aspect="equal")
        ax.set(xlabel="x (m)", ylabel="y (m)")
        grid(ax)
        ax.legend(loc="upper right", fontsize=8, markerscale=4)
        title = ax.set_title("", fontsize=10)
        return {"path": path, "scan": scan, "here": here, "loops": loops, "title": title}

    def _draw(self, artists: dict, frame: Frame):
        path = frame.trajectory
        artists["path"].set_data(path[:, 0], path[:, 1])
        artists["here"].set_data(path[-1:, 0], path[-1:, 1])
        artists["scan"].set_offsets(frame.scan if len(frame.scan) else np.empty((0, 2)))
        pairs = np.array(frame.loops, int).reshape(-1, 2)
        artists["loops"].set_segments(segments(path[pairs[:, 0]], path[pairs[:, 1]]) if len(pairs) else [])
        n = len(frame.loops)
        artists["title"].set_text(f"scan {frame.index}, node {frame.node}: {n} loop edge{'' if n == 1 else 's'} so far")
        return list(artists.values())
