"""The edges back in a helper process (helpers.slam.edges_back): the same run to the bit as in place, also
when the process cannot start or dies halfway, and a failure inside it raised as in place."""

import io
import logging
import os
import pickle
import re
import signal
import struct
import time
from contextlib import contextmanager

import numpy as np
import pytest

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.slam import edges_back
from helpers.slam.edges_back import STARTUP_NODES, BackgroundEdges, serve
from helpers.slam.pipeline import run_slam
from helpers.slam.slam import Slam

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
    monkeypatch.setattr("helpers.slam.pipeline.STARTUP_NODES", 30)
    assert STARTUP_NODES > 30
    _same(run_slam(stretch, Config()), in_place)
    assert started


def test_a_helper_process_that_dies_halfway_leaves_the_same_run(stretch, in_place, caplog):
    def kill_at_node_12(slam, node):
        if node == 12:
            assert isinstance(slam.edges_back, BackgroundEdges) and slam.edges_back.process is not None
            slam.edges_back.process.kill()
            slam.edges_back.process.wait()

    with caplog.at_level(logging.WARNING, logger="helpers.slam.edges_back"):
        survived = _slam(stretch, background=True, on_node=kill_at_node_12)
    _same(survived, in_place)
    assert "registering them in this process" in caplog.text


def test_a_helper_process_that_cannot_start_leaves_the_same_run(stretch, in_place, monkeypatch, caplog):
    monkeypatch.setattr("sys.executable", "/nonexistent/python")
    with caplog.at_level(logging.WARNING, logger="helpers.slam.edges_back"):
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
    replies = [pickle.loads(answers.read(struct.unpack("<Q", answers.read(8))[0])) for _ in range(3)]
    assert answers.read() == b""
    assert [kind for kind, *_ in replies[:2]] == ["edges", "edges"]  # nodes 0 and 1 have no scan 2 back
    kind, error, tried, seconds = replies[2]
    assert kind == "error" and isinstance(error, SlamError) and "points" in str(error) and tried == 0
    assert seconds >= 0


def test_a_run_left_without_its_result_exits_quietly_and_leaves_no_process(tmp_path):
    """A script that stops before Slam.result(): its helper, answering into a closed pipe, ends without a
    traceback, and the script's exit status is its own."""
    import subprocess
    import sys

    script = (
        "import helpers, os\n"
        "from helpers.config.tables import Config\n"
        "from helpers.slam.slam import Slam\n"
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


# Issue 63: no wait on the helper process without a bound. A watchdog fails a test whose run would hang instead.


class _Hung(Exception):
    """The run still waited on the helper process after the watchdog's minutes (caught by nothing)."""


@contextmanager
def _watchdog(seconds: int = 240):
    def hung(signum, frame):
        raise _Hung(f"the run still waited after {seconds} s")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def test_a_stopped_helper_process_is_noticed_and_the_run_is_the_same(stretch, in_place, caplog):
    def stop_at_node_12(slam, node):
        if node == 12:
            os.kill(slam.edges_back.process.pid, signal.SIGSTOP)  # kill -STOP, a debugger, a frozen container

    with caplog.at_level(logging.WARNING, logger="helpers.slam.edges_back"), _watchdog():
        survived = _slam(stretch, background=True, on_node=stop_at_node_12)
    _same(survived, in_place)
    (warning,) = [r.getMessage() for r in caplog.records]
    assert warning == "the edges back's helper process failed (it was stopped): registering them in this process"


NEVER_ANSWERS = "import sys; sys.stdin.buffer.read()"  # reads every request, answers none
STALLS_AT_NODE_12 = """
import time
from helpers.slam import edges_back
add = edges_back.EdgesBack.add
def stall(self, j, clouds, relative):
    if j == 12:
        time.sleep(3600)
    return add(self, j, clouds, relative)
edges_back.EdgesBack.add = stall
edges_back.main()
"""


@pytest.mark.parametrize("helper", ["never answers", "stalls at node 12"])
def test_a_helper_process_that_does_not_answer_is_given_up_after_its_bound(
    stretch, in_place, monkeypatch, caplog, helper
):
    """Bounds made short here (the stand-ins never answer, so any bound is reached): half a second for the
    first answer, or twice the slowest node so far and at least half a second."""
    if helper == "never answers":
        monkeypatch.setattr(edges_back, "HELPER", NEVER_ANSWERS)
        monkeypatch.setattr(edges_back, "FIRST_WAIT_S", 0.5)
    else:
        monkeypatch.setattr(edges_back, "HELPER", STALLS_AT_NODE_12)
        monkeypatch.setattr(edges_back, "MIN_WAIT_S", 0.5)
        monkeypatch.setattr(edges_back, "WAIT_FACTOR", 2.0)
    with caplog.at_level(logging.WARNING, logger="helpers.slam.edges_back"), _watchdog():
        survived = _slam(stretch, background=True)
    _same(survived, in_place)
    (warning,) = [r.getMessage() for r in caplog.records]
    assert re.fullmatch(
        r"the edges back's helper process failed \(no answer in [0-9.]+ s\): registering them in this process", warning
    )


def test_the_helper_process_reads_the_openmp_wait_policy_in_any_locale(monkeypatch):
    """libgomp compares it in the user's locale: in Turkish, "PASSIVE" is not "passive" (tests/test_faults.py)."""
    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    environment = edges_back.helper_environment()
    assert environment["OMP_WAIT_POLICY"] == "passive" and environment["OMP_NUM_THREADS"] == "1"
