"""The live view of the main loop: one frame per accepted scan, holding what
``Slam.process`` did; a single picture updated in place in a kernel; an
animation that needs nothing from the network."""

import base64
import hashlib
import os
import re

import nbformat
import numpy as np
import pytest
from nbclient import NotebookClient

from helpers.config.tables import Config
from helpers.slam.odometry import OdometryResult
from helpers.slam.pipeline import Slam
from helpers.viz.live import LiveView

# A short loop has few submaps; no edges back: the view shows odometry and loops.
SHORT = Config().with_values(loop_closure=dict(sub_map_thresh=3), pose_graph=dict(edges_back=1))


def true_odometry(data, skip: int) -> OdometryResult:
    """An odometry that is the truth, so the run only closes loops (fast, and every loop is a real one)."""
    indices = np.arange(0, len(data), skip)
    poses = data.poses[indices]
    relative = np.linalg.inv(poses[:-1]) @ poses[1:]
    zeros = np.zeros(len(indices) - 1)
    return OdometryResult(indices, poses, relative, zeros, zeros, zeros, {})


@pytest.fixture(scope="module")
def recorded(short_loop):
    slam = Slam(SHORT, anchor=short_loop.poses[0], odometry=true_odometry(short_loop, SHORT.registration.skip_frames))
    live = LiveView(short_loop.poses, show=False)
    steps = []
    for index, scan in enumerate(short_loop.scans):
        steps.append(slam.process(scan, index))
        live.update(steps[-1], scan)
    return short_loop, steps, live


def test_one_frame_per_accepted_scan_holding_what_the_step_did(recorded):
    data, steps, live = recorded
    accepted = [step for step in steps if step.accepted]
    assert len(accepted) < len(steps), "the run skipped no scan: skip_frames not exercised"
    assert [(f.node, f.index) for f in live.frames] == [(s.node, s.index) for s in accepted]
    truth = data.poses[[s.index for s in accepted], :2, 3]
    for k, frame in enumerate(live.frames):
        np.testing.assert_allclose(frame.trajectory, truth[: k + 1], atol=1e-9)  # the odometry so far
        # the scan's points, moved into the map frame, lie around the drone as far as the scan reaches
        reach = np.linalg.norm(data.scans[accepted[k].index][:, :2], axis=1).max()
        assert len(frame.scan) == live.sample
        assert np.linalg.norm(frame.scan - truth[k], axis=1).max() <= reach + 1e-6
    closed = [(s.loop.i, s.loop.j) for s in accepted if s.loop is not None]
    assert closed, "the short loop closed no loop: the view's loop edges are not exercised"
    assert list(live.frames[-1].loops) == closed
    first = next(k for k, s in enumerate(accepted) if s.loop is not None)
    assert live.frames[first - 1].loops == () and live.frames[first].loops == (closed[0],)


def test_the_animation_is_self_contained_and_light(recorded):
    _, _, live = recorded
    html = live.animation(frames=12)
    frames = re.findall(r"data:image/jpeg;base64,", html)
    assert len(frames) == 12
    assert not re.search(r"https?://", html), "the animation asks for something off the machine"
    assert "font-awesome" not in html and 'class="fa ' not in html
    assert len(html) < 400_000, f"{len(html) / 1e3:.0f} kB"
    with pytest.raises(ValueError, match="no frame"):
        LiveView(np.zeros((2, 2)), show=False).animation()


def test_in_a_kernel_the_view_is_one_picture_updated_in_place():
    """As JupyterLab runs it: many redraws, one output, showing the last frame."""
    code = """
import numpy as np
from helpers.slam.slam import Step
from helpers.viz.live import LiveView
truth = np.zeros((30, 4, 4)); truth[:] = np.eye(4); truth[:, 0, 3] = np.arange(30.0)
live = LiveView(truth, every=3)
for k in range(30):
    live.update(Step(k, True, k, truth[k]), np.random.default_rng(k).normal(size=(50, 3)))
live.finish()
print(len(live.frames), "frames")
"""
    last = """
import hashlib
from helpers.viz import render
print("last frame:", hashlib.sha1(render.show_figure(live.figure()).data).hexdigest())
"""
    notebook = nbformat.v4.new_notebook()
    notebook.cells = [nbformat.v4.new_code_cell(code), nbformat.v4.new_code_cell(last)]
    NotebookClient(notebook, timeout=120, resources={"metadata": {"path": os.getcwd()}}).execute()
    outputs = notebook.cells[0].outputs
    pictures = [o for o in outputs if o.output_type == "display_data"]
    assert len(pictures) == 1 and "image/png" in pictures[0].data, [o.output_type for o in outputs]
    assert any("30 frames" in o.get("text", "") for o in outputs)
    shown = hashlib.sha1(base64.b64decode(pictures[0].data["image/png"])).hexdigest()
    assert f"last frame: {shown}" in notebook.cells[1].outputs[0].text, "the picture is not the last frame"
