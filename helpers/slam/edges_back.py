"""The edges back in a helper process, one node behind the main loop.

The edges back are a third of a run's time (the default flight's 680 ICPs,
one thread each: small_gicp holds Python's lock, so a thread would not
help) and nothing in a node's odometry waits for them: only the next loop
query reads them, through the loop closer's uncertainty graph. So while the
main process registers node j + 1, this process registers node j onto the
scans before it, and :class:`BackgroundEdges` hands node j's edges over just
before node j + 1's loop query, where :class:`EdgesBack` in
the main process would have added them. The same code on the same points
and steps in the same order gives the same edges to the bit, so a run is
the same run either way; only the time changes.

The process is a fresh Python running :func:`main`, not a fork of the main
process (OpenMP does not survive a fork) nor a ``multiprocessing`` spawn
(which re-runs a user's script that has no ``__main__`` guard). It reads
pickled messages on its stdin and answers on what was its stdout (the
libraries' own prints go to stderr instead). If it cannot start, dies, is
stopped or stalls, the main process warns once and registers the edges back
itself; it never waits on the process without a bound.
"""

from __future__ import annotations

import logging
import os
import pickle
import select
import struct
import subprocess
import sys
import time
from contextlib import suppress
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from helpers.slam.graph.factors import Edge

if TYPE_CHECKING:
    from helpers.slam.registration.icp_service import IcpService

log = logging.getLogger(__name__)

STARTUP_NODES = 50  # a run of fewer nodes registers in place: starting the process (imports) costs about a second
HELPER = "from helpers.slam.edges_back import main; main()"  # what the helper process runs
# How long the main process waits for the helper: the first answer includes the helper's start (its imports);
# a later one may take WAIT_FACTOR times the slowest node so far, at least MIN_WAIT_S. A helper given up on
# costs only time: the main process registers its nodes, to the same bits.
FIRST_WAIT_S, MIN_WAIT_S, WAIT_FACTOR = 60.0, 10.0, 20.0
POLL_S = 0.25  # how often a wait checks that the helper is still running and not stopped


class EdgesBack:
    """Registers every node to the nodes 2 .. ``edges_back`` before it, from
    the chained odometry as the guess. Each extra edge measures the motion
    again with other points, so the pose graph can average the odometry's
    random errors instead of summing them. Registrations scored above
    ``rmse_threshold`` (surface RMSE) are left out.

    ICP starts close and stops after ``max_iterations``: some edges never
    meet the tolerance but oscillate by millimetres until any cap, and a low
    cap gives the same trajectory sooner (notebook 6 and the benchmarks
    measure it)."""

    def __init__(self, icp: IcpService, *, edges_back: int, max_iterations: int, rmse_threshold: float) -> None:
        self.icp, self.edges_back, self.max_iterations = icp, edges_back, max_iterations
        self.rmse_threshold = rmse_threshold
        self.edges: list[Edge] = []
        self.tried = 0

    @classmethod
    def from_config(cls, icp: IcpService, graph) -> EdgesBack:
        """The edges back of ``[pose_graph]`` (``graph``), registered by ``icp``."""
        return cls(
            icp,
            edges_back=graph.edges_back,
            max_iterations=graph.edges_back_icp_max_iterations,
            rmse_threshold=graph.edges_back_rmse_threshold,
        )

    def add(self, j: int, clouds, relative) -> list[Edge]:
        """The edges back of node ``j`` (``clouds[k]``: node k's cloud, ``relative[k]``: the odometry
        step from node k to k + 1; lists, or dicts of the nodes within reach)."""
        kept = []
        for back in range(2, min(self.edges_back, j) + 1):
            guess = np.linalg.multi_dot([np.eye(4), *(relative[k] for k in range(j - back, j))])
            fit = self.icp(
                moving=clouds[j], fixed=clouds[j - back], T_fixed_moving=guess, max_iterations=self.max_iterations
            )
            (T_i_j, rmse), self.tried = fit, self.tried + 1
            if rmse < self.rmse_threshold:
                kept.append(Edge(j - back, j, T_i_j, rmse, information=fit.information))
            else:
                log.info("edge %d -> %d left out: surface RMSE %.2f m", j - back, j, rmse)
        self.edges.extend(kept)
        return kept

    def sorted(self) -> list[Edge]:
        """Every kept edge, ordered by span, then by node."""
        return sorted(self.edges, key=lambda e: (e.j - e.i, e.j))


class BackgroundEdges:
    """:class:`EdgesBack` (``local``) run in a helper process: :meth:`submit` node j's scan
    and steps, :meth:`collect` its kept edges at the next node. ``edges``, ``tried`` and :meth:`sorted`
    are ``local``'s, which also registers any node the process could not. No wait is unbounded: a
    helper that dies or is stopped is noticed within :data:`POLL_S`, one that stalls once it has taken
    :data:`WAIT_FACTOR` times its slowest node (:data:`FIRST_WAIT_S` for the first, which includes its start)."""

    def __init__(self, local, config) -> None:
        self.local, self.pending, self.process, self.slowest = local, None, None, None
        try:
            self.process = subprocess.Popen(
                [sys.executable, "-c", HELPER],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                env=helper_environment(),
                bufsize=0,
            )
            os.set_blocking(self.process.stdin.fileno(), False)  # a write that would block waits in _wait
            self._send(("start", config))
        except _LOST as exc:
            self._give_up(exc)

    def submit(self, j: int, clouds, relative) -> None:
        """Start node ``j``'s edges back (``clouds`` of nodes 0 .. j, ``relative`` the odometry steps)."""
        self.pending = (j, clouds, relative)
        if self.process is not None:
            steps = {k: relative[k] for k in range(max(0, j - self.local.edges_back), j)}
            try:
                self._send(("node", j, clouds[j], steps))
            except _LOST as exc:
                self._give_up(exc)

    def collect(self) -> list:
        """The kept edges back of the node last submitted ([] if none is pending)."""
        if self.pending is None:
            return []
        j, clouds, relative = self.pending
        if self.process is not None:
            try:
                kind, value, tried, seconds = pickle.loads(self._read(struct.unpack("<Q", self._read(8))[0]))
            except _LOST as exc:  # interrupted reads end here too
                self._give_up(exc)
            else:
                self.pending = None
                self.slowest = max(self.slowest or 0.0, seconds)
                if kind == "error":
                    raise value  # what the main process would have raised for this node
                self.local.edges.extend(value)
                self.local.tried += tried
                return value
        self.pending = None
        return self.local.add(j, clouds, relative)

    def sorted(self) -> list:
        return self.local.sorted()

    @property
    def tried(self) -> int:
        return self.local.tried

    def close(self) -> None:
        """Stop the process (a run's result has every edge); idempotent."""
        if self.process is not None:
            process, self.process = self.process, None
            for pipe in (process.stdin, process.stdout):
                pipe.close()
            try:
                process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()

    def _send(self, message) -> None:
        data = memoryview(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))
        fd, started = self.process.stdin.fileno(), time.monotonic()
        while data:
            self._wait(fd, started, write=True)
            with suppress(BlockingIOError):
                data = data[os.write(fd, data) :]

    def _read(self, size: int) -> bytes:
        data, fd, started = bytearray(), self.process.stdout.fileno(), time.monotonic()
        while len(data) < size:
            self._wait(fd, started, write=False)
            chunk = os.read(fd, size - len(data))
            if not chunk:
                raise EOFError("it closed its answers")
            data += chunk
        return bytes(data)

    def _wait(self, fd: int, started: float, write: bool) -> None:
        """Until ``fd`` is ready, checking every :data:`POLL_S` that the helper runs and has not taken too long."""
        bound = FIRST_WAIT_S if self.slowest is None else max(MIN_WAIT_S, WAIT_FACTOR * self.slowest)
        readers, writers = ([], [fd]) if write else ([fd], [])
        while not any(select.select(readers, writers, [], POLL_S)[:2]):
            if self.process.poll() is not None:
                raise EOFError(f"it ended (exit status {self.process.returncode})")
            if _stopped(self.process.pid):
                raise _Stalled("it was stopped")
            if time.monotonic() - started > bound:
                raise _Stalled(f"no answer in {bound:.3g} s")

    def _give_up(self, exc) -> None:
        log.warning("the edges back's helper process failed (%s): registering them in this process", exc)
        process, self.process = self.process, None
        if process is not None:
            process.kill()
            process.wait()

    def __del__(self):
        try:
            self.close()
        except Exception:  # at interpreter exit the modules close() needs may be gone; the process ends on EOF
            pass


class _Stalled(Exception):
    """The helper process was stopped, or took far longer than its nodes take."""


_LOST = (OSError, EOFError, pickle.UnpicklingError, _Stalled)  # how the helper process is lost


def _stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (SIGSTOP, a debugger), from Linux's ``/proc``; False where unknown."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] in (b"T", b"t")
    except (OSError, IndexError):
        return False


def helper_environment() -> dict[str, str]:
    """The helper's environment: this process's, the package the main process imported first on the path,
    one thread (the main process keeps the others busy; a k-d tree or a covariance is the same on any number),
    and ``OMP_WAIT_POLICY`` in lower case, which libgomp reads in every locale (``PASSIVE``'s I is not an i in
    Turkish)."""
    package_parent = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (package_parent, os.environ.get("PYTHONPATH"))))}
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if "OMP_WAIT_POLICY" in env:
        env["OMP_WAIT_POLICY"] = env["OMP_WAIT_POLICY"].lower()
    return env


def serve(requests, answers) -> None:
    """Answer ``("node", j, cloud, steps)`` requests with ``("edges", kept, tried, seconds)`` (or ``("error",
    exception, 0, seconds)``), each framed by its length (8 bytes, little-endian), until the main process closes
    the pipe; ``("start", config)`` comes first."""
    from helpers.slam.registration.icp_service import IcpService

    clouds, steps, edges = {}, {}, None
    while True:
        try:
            message = pickle.load(requests)
        except EOFError:
            return
        if message[0] == "start":
            config = message[1]
            icp = IcpService.from_config(config.registration, pose_graph=config.pose_graph)
            edges = EdgesBack.from_config(icp, config.pose_graph)
            continue
        _, j, cloud, new_steps = message
        clouds[j] = cloud
        steps.update(new_steps)
        for table in (clouds, steps):  # keep what the next node's edges back can reach
            for old in [k for k in table if k < j - edges.edges_back]:
                del table[old]
        tried, started = edges.tried, time.perf_counter()
        try:
            answer = ("edges", edges.add(j, clouds, steps), edges.tried - tried)
        except Exception as exc:  # the main process raises it, as it would have raised it itself
            answer = ("error", exc, 0)
        data = pickle.dumps((*answer, time.perf_counter() - started), protocol=pickle.HIGHEST_PROTOCOL)
        answers.write(struct.pack("<Q", len(data)) + data)
        answers.flush()


def main() -> None:
    """The helper process: answers on a copy of stdout, which then points at stderr."""
    answers = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # a library's print must not land in the answers
    sys.stdout = sys.stderr
    try:
        serve(sys.stdin.buffer, answers)
    except BrokenPipeError:  # the main process is gone: nobody to answer, nothing to clean up
        os._exit(0)
