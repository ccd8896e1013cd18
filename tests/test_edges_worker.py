"""The edges back in a helper process (helpers.edges_worker): the same run to the bit as in place, also
when the process cannot start or dies halfway, and a failure inside it raised as in place."""

import io
import logging
import os
import pickle
import time

import numpy as np
import pytest

from helpers.config import Config
from helpers.edges_worker import STARTUP_NODES, BackgroundEdges, serve
from helpers.errors import SlamError
from helpers.pipeline import run_slam
from helpers.slam import Slam

SCANS = 90  # 30 nodes at the default skip_frames = 3, each with up to 3 edges back


@pytest.fixture(scope="module")
def stretch(flight_over):
    return flight_over(slice(0, SCANS))


def _slam(data, background, *, on_node=None):
    """A run of ``data`` through :class:`Slam`; ``on_node(slam, node)`` is called after every node."""
    slam = Slam(Config(), anchor=data.poses[0], background=background)
    for index in range(len(data)):
        if slam.accepts(index):
            step = slam.process(data.scans[index], index)
            if on_node is not None:
                on_node(slam, step.node)
    return slam.result(n_scans=len(data))


@pytest.fixture(scope="module")
def in_place(stretch):
    return _slam(stretch, background=False)


def _same(a, b):
    assert np.array_equal(a.poses_optimized, b.poses_optimized)
    assert a.edges_back_tried == b.edges_back_tried and len(a.extra_edges) == len(b.extra_edges) > 0
    for x, y in zip(a.extra_edges, b.extra_edges, strict=True):
        assert (x.i, x.j) == (y.i, y.j)
        assert np.array_equal(x.relative, y.relative) and np.array_equal(x.information, y.information)


def test_the_helper_process_gives_the_run_of_the_main_process(stretch, in_place, monkeypatch):
    """run_slam starts the process from STARTUP_NODES nodes on (lowered here to this stretch's 30)."""
    started = []
    original = BackgroundEdges.__init__

    def spy(self, *args):
        started.append(True)
        original(self, *args)

    monkeypatch.setattr(BackgroundEdges, "__init__", spy)
    monkeypatch.setattr("helpers.pipeline.STARTUP_NODES", 30)
    assert STARTUP_NODES > 30
    _same(run_slam(stretch, Config()), in_place)
    assert started


def test_a_helper_process_that_dies_halfway_leaves_the_same_run(stretch, in_place, caplog):
    def kill_at_node_12(slam, node):
        if node == 12:
            assert isinstance(slam.edges_back, BackgroundEdges) and slam.edges_back.process is not None
            slam.edges_back.process.kill()
            slam.edges_back.process.wait()

    with caplog.at_level(logging.WARNING, logger="helpers.edges_worker"):
        survived = _slam(stretch, background=True, on_node=kill_at_node_12)
    _same(survived, in_place)
    assert "registering them in this process" in caplog.text


def test_a_helper_process_that_cannot_start_leaves_the_same_run(stretch, in_place, monkeypatch, caplog):
    monkeypatch.setattr("sys.executable", "/nonexistent/python")
    with caplog.at_level(logging.WARNING, logger="helpers.edges_worker"):
        _same(_slam(stretch, background=True), in_place)
    assert "failed" in caplog.text


def test_a_failure_in_the_helper_process_is_answered_as_the_main_process_would_raise_it():
    """A node whose cloud ICP refuses (two points) is answered with the error, and the process goes on."""
    requests = io.BytesIO()
    for message in (
        ("start", Config()),
        ("node", 0, np.zeros((2, 3)), {}),
        ("node", 1, np.zeros((2, 3)), {0: np.eye(4)}),
        ("node", 2, np.zeros((2, 3)), {1: np.eye(4)}),
    ):
        pickle.dump(message, requests)
    requests.seek(0)
    answers = io.BytesIO()
    serve(requests, answers)
    answers.seek(0)
    replies = [pickle.load(answers) for _ in range(3)]
    assert [kind for kind, *_ in replies[:2]] == ["edges", "edges"]  # nodes 0 and 1 have no scan 2 back
    kind, error, tried = replies[2]
    assert kind == "error" and isinstance(error, SlamError) and "points" in str(error) and tried == 0


def test_a_run_left_without_its_result_exits_quietly_and_leaves_no_process(tmp_path):
    """A script that stops before Slam.result(): its helper, answering into a closed pipe, ends without a
    traceback, and the script's exit status is its own."""
    import subprocess
    import sys

    script = (
        "import helpers, os\n"
        "from helpers.config import Config\n"
        "from helpers.slam import Slam\n"
        "data = helpers.create_dataset()\n"
        "slam = Slam(Config(), anchor=data.poses[0], background=True)\n"
        "for i in range(0, 30, 3):\n"
        "    slam.process(data.scans[i], i)\n"
        "print(slam.edges_back.process.pid)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr
    helper = int(done.stdout.split()[-1])
    for _ in range(50):  # the helper reads the end of its input and stops
        try:
            os.kill(helper, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        pytest.fail(f"the helper process {helper} is still running")
