"""The notebooks' "pcplayer": scans seen from above, played as an HTML
animation whose frames are embedded, so it plays in a static HTML export
and offline."""

from __future__ import annotations

import re

import matplotlib.pyplot as plt
import numpy as np

from helpers.viz.style import DPI, HEIGHT_CMAP, TEXT_PT

# An animation's frames are drawn at the figures' DPI and shown at that size, so their text is as large as a
# figure's (10 pt: 11 px); the notebook embeds every frame, so they are not drawn larger. JPEG of Pillow's
# default quality.
FRAME_DPI = DPI
FRAME_QUALITY = 75

# Matplotlib's animation buttons draw Font Awesome icons fetched from a CDN,
# blank offline; these characters need no font download.
PLAYER_ICONS = {
    "fa-minus": "\u2212",  # slower
    "fa-fast-backward": "\u21e4",  # first frame
    "fa-step-backward": "\u25c1",  # previous frame
    "fa-play fa-flip-horizontal": "\u25c0",  # play backwards
    "fa-pause": "\u2016",
    "fa-play": "\u25b6",
    "fa-step-forward": "\u25b7",  # next frame
    "fa-fast-forward": "\u21e5",  # last frame
    "fa-plus": "+",  # faster
}


def top_down(points: np.ndarray, half_width: float, half_length: float, cell: float = 1.0) -> np.ndarray:
    """Rasterise sensor-frame points seen from above: the highest z per cell,
    gaps narrower than 3 m (between rays 2 m apart along the track) filled
    from the nearest cell, NaN farther out. Rows run along x (forward),
    columns along y (draw it with an inverted x axis to put the drone's
    left, +y, on the left as seen from above)."""
    from scipy import ndimage

    rows, cols = int(2 * half_length / cell), int(2 * half_width / cell)
    i = np.floor((points[:, 0] + half_length) / cell).astype(int)
    j = np.floor((points[:, 1] + half_width) / cell).astype(int)
    inside = (i >= 0) & (i < rows) & (j >= 0) & (j < cols)
    image = np.full(rows * cols, -np.inf)
    np.maximum.at(image, i[inside] * cols + j[inside], points[inside, 2])
    image = image.reshape(rows, cols)
    empty = np.isinf(image)
    distance, (ni, nj) = ndimage.distance_transform_edt(empty, return_indices=True)
    image = image[ni, nj]
    image[distance * cell > 1.5] = np.nan
    return image


def scan_player(scans: list[np.ndarray], indices, interval_ms: int = 200, size=(7.5, 2.6)):
    """An HTML animation (play, pause, step) of scans seen from above in the
    sensor frame, coloured by height: the notebook's "pcplayer". The frames
    are embedded, so it plays in a static HTML export too; ``size`` (inches)
    is shown at the figures' DPI, its text no smaller than theirs."""
    from matplotlib import animation

    indices = list(indices)
    every = np.concatenate([scans[i] for i in indices])
    lo, hi = np.percentile(every[:, 2], [0.5, 99.5])
    half_w = np.ceil(np.abs(every[:, 1]).max())
    half_l = np.ceil(np.abs(every[:, 0]).max())
    extent = (-half_w, half_w, -half_l, half_l)
    fig, ax = plt.subplots(figsize=size)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.2, top=0.88)  # fixed: a layout engine per frame is slow
    image = ax.imshow(
        top_down(scans[indices[0]], half_w, half_l),
        origin="lower",
        extent=extent,
        cmap=HEIGHT_CMAP,
        vmin=lo,
        vmax=hi,
        interpolation="nearest",
    )
    bar = fig.colorbar(image, ax=ax, pad=0.01)
    bar.set_label("z, sensor frame (m)", fontsize=TEXT_PT)
    bar.ax.tick_params(labelsize=TEXT_PT)
    ax.set(xlabel="y, to the left of the drone (m)", ylabel="x, forward (m)")
    ax.invert_xaxis()  # seen from above with x up, +y is on the left
    label = ax.set_title("")

    def draw(frame):
        image.set_data(top_down(scans[indices[frame]], half_w, half_l))
        label.set_text(f"scan {indices[frame]} seen from the drone")
        return image, label

    anim = animation.FuncAnimation(fig, draw, frames=len(indices), interval=interval_ms, blit=False)
    html = embedded_frames(anim, interval_ms, "loop")
    plt.close(fig)
    return offline_player(html, round(size[0] * DPI))


def embedded_frames(anim, interval_ms: int, mode: str, dpi: int = FRAME_DPI, quality: int = FRAME_QUALITY) -> str:
    """``anim`` as matplotlib's HTML animation (``Animation.to_jshtml``), its frames JPEGs of ``quality``
    drawn at ``dpi``, which ``to_jshtml`` does not let one choose."""
    import tempfile
    from pathlib import Path

    from matplotlib import animation

    writer = animation.HTMLWriter(fps=1000 / interval_ms, embed_frames=True, default_mode=mode)
    writer.frame_format = "jpeg"
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder, "animation.html")
        anim.save(str(path), writer=writer, dpi=dpi, savefig_kwargs={"pil_kwargs": {"quality": quality}})
        return path.read_text()


def offline_player(html: str, width: int | None = None) -> str:
    """Matplotlib's animation HTML without its one network resource: the
    Font Awesome style sheet goes, and each button icon becomes a character.
    ``width``: the CSS pixels its frames are shown at (they are drawn larger, to stay sharp)."""
    html = re.sub(r"<link[^>]*font-awesome[^>]*>\s*", "", html)
    if width is not None:
        html = re.sub(r'(<img id="_anim_img\w*")', rf'\1 width="{width}"', html, count=1)
    return re.sub(r'<i class="fa ([^"]+)"></i>', lambda m: PLAYER_ICONS.get(m.group(1), m.group(0)), html)
