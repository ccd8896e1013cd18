"""How sure the pose graph is of where the current scan lies relative to an
old place, and the loop search's gate built on it (issue 21, item 5).

:class:`RelativeUncertainty` keeps the graph as the run grows it: one node
per accepted scan at its odometry pose, the odometry steps, the edges back
and the loop edges, each with its noise (:func:`edge_information`). It
answers two questions: where the graph puts an old node ``c`` relative to the
current one (the odometry's offset, moved by the loop edges found), and how
uncertain that offset is (its covariance). A loop query turns them into a
gate (:func:`helpers.slam.loops.search.mahalanobis_gate`): an old submap is searched when its centre
could, within ``search_sigmas`` sigmas, lie within the fixed search radius
of the scan. With no uncertainty the gate is the reference's fixed radius;
drift widens it only where the graph says drift can be, and a loop shrinks
it (and moves the old places to where the loop says they are: a narrow gate
around the odometry's offset would miss them).

The covariance, in GTSAM's conventions (a pose ``T = T_hat @ Exp(xi)``,
``xi`` rotation first): hold node ``m`` fixed (a stiff prior on it and on no
other node), eliminate the graph linearised at the odometry poses once, and
its solution moves every node where the graph puts it while the marginal
covariance of node ``c`` (as ``gtsam.Marginals`` gives it) is the covariance
of ``c`` relative to ``m``. Computing them is the costly part,
so it is done at most once per query, anchored at the node that asks, and
reused while it stays valid: for the next few nodes the chain of odometry
steps since ``m`` is compounded (``Sigma <- Ad(S^-1) Sigma Ad(S^-1)^T + Q``)
and added through the adjoint. A new loop edge makes it stale (loops are what
shrink it); so does a chain grown to :data:`REFRESH_NODES` nodes. The chain
leaves out the edges back among its nodes, so the reused answer errs on the
wide side. Only the nodes a query may let in are computed anew; the others
keep the answer carried over from the last computation, which edges added
since can only have narrowed (a gate that refuses a node under the carried
answer refuses it under the exact one).

On a long flight the graph grows without end, and so would the cost of
eliminating it. Each computation therefore takes a window: the
:data:`WINDOW_NODES` nodes nearest the anchor along the graph's edges (a
breadth-first search over odometry steps, edges back and loop edges,
:func:`helpers.slam.loops.window.window_of`), with the edges among them. A
graph with fewer edges is less sure, so a window's covariances err on the
wide side, as a carried answer does. A node outside the window has no answer
(NaN): the loop search leaves its place out. When no node of the window
could be in reach (a first revisit, which only the long way round the graph
joins to the scan), the whole graph is computed once for that anchor, as on
a short flight.

The graph is linearised at the odometry poses (they never change during a
run). Loop edges enter it as plain Gaussians: a false loop would move the old
places near it and narrow the gate around the wrong spot.

GNSS fixes (:meth:`RelativeUncertainty.add_fix`) hold the graph in the map
frame. Where the window holds at least :data:`MIN_FIXES` of them, it is first
solved with the fixes (Levenberg-Marquardt, from the last such solution),
and linearised there rather than at the odometry: after a turn the odometry
missed (a field too flat to see it turn), the flight bends back to where the
fixes say it flew, and the old places, the gate and ICP's start follow. The
answers are then expressed in the frame where the anchor lies at its
odometry pose, as without fixes; the covariance is the anchor-held one, so
that the fixes near the current node narrow it a little more than the
covariance of the offset alone would.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np

from helpers.config.tables import PoseGraphConfig
from helpers.errors import SlamError
from helpers.geometry import adjoint
from helpers.slam.graph.factors import Edge, edge_information, gaussian, pose3
from helpers.slam.graph.information import swap_blocks
from helpers.slam.loops.window import held_solve, matrices, window_of

REFRESH_NODES = 12  # recompute the marginals once the chain since the last computation holds this many nodes
WINDOW_NODES = 800  # the nodes a computation holds at most: the anchor's neighbourhood along the graph's edges
ANCHOR_SIGMA = 1e-6  # the prior holding the anchor node: far stiffer than any edge, still well conditioned
MIN_FIXES = 3  # GNSS fixes a window must hold before they, not the anchor's odometry pose, place it


class RelativeUncertainty:
    """The run's pose graph for two questions: where does it put an old node
    relative to the current one, and how uncertain is that offset (see the
    module's docstring)::

        graph = RelativeUncertainty(config.pose_graph)
        graph.add_node(pose)  # each accepted scan, in order (odometry step from the previous one)
        graph.add_edge(edge)  # an edge back; graph.add_edge(loop, loop=True) for a loop edge
        graph.add_fix(node, position, sigmas)  # a GNSS fix of a node, if the flight has them
        cov = graph.position_covariances(old_nodes)  # (K, 3, 3), map frame, m²
        where = graph.positions(old_nodes)  # (K, 3), map frame, beside the current node's odometry position

    ``seconds``, ``refreshes`` and ``answers`` say what the answers cost;
    ``whole`` counts the computations that needed the whole graph.
    """

    def __init__(
        self, settings: PoseGraphConfig, refresh_nodes: int = REFRESH_NODES, window_nodes: int = WINDOW_NODES
    ) -> None:
        self.settings, self.refresh_nodes, self.window_nodes = settings, refresh_nodes, window_nodes
        self.poses: list[np.ndarray] = []
        self.seconds, self.refreshes, self.answers, self.whole = 0.0, 0, 0, 0
        self._factors: list[gtsam.BetweenFactorPose3] = []
        self._ends: list[tuple[int, int]] = []  # the two nodes each factor joins
        self._pose3: list[gtsam.Pose3] = []
        self._touching: list[list[int]] = []  # node -> the factors that join it to another node
        self._anchor: int | None = None  # the node the cached marginals are relative to
        self._tree = None  # the window held at the anchor, eliminated: its marginals and its solution
        self._window = np.zeros(0, dtype=bool)  # node -> whether the anchor's window holds it
        self._solved = np.zeros((0, 4, 4))  # where the graph held at the anchor puts each node (map frame)
        self._cached: dict[int, np.ndarray] = {}  # node -> its 6 x 6 covariance relative to the anchor
        self._exact: set[int] = set()  # the nodes whose cached covariance came from the anchor's marginals
        self._chain = np.zeros((6, 6))  # the current node relative to the anchor, along the odometry steps
        self._due = False  # a loop edge came since the anchor's marginals
        self._fixes: dict[int, gtsam.GPSFactor] = {}  # node -> its GNSS fix
        self._held: dict[int, gtsam.Pose3] = {}  # node -> where the last solve with fixes put it (map frame)
        self._linear = np.zeros((0, 4, 4))  # node -> where the fixes placed it, if they did (see _about)

    @property
    def num_nodes(self) -> int:
        return len(self.poses)

    @property
    def graph(self) -> gtsam.NonlinearFactorGraph:
        """Every edge so far (odometry steps, edges back, loop edges) as GTSAM factors: the whole graph."""
        graph = gtsam.NonlinearFactorGraph()
        for factor in self._factors:
            graph.add(factor)
        return graph

    @property
    def values(self) -> gtsam.Values:
        """Every node at its odometry pose."""
        values = gtsam.Values()
        for node, pose in enumerate(self._pose3):
            values.insert(node, pose)
        return values

    def add_node(self, pose: np.ndarray, step: Edge | None = None) -> int:
        """Node ``num_nodes`` at its odometry pose, joined to the previous one by
        ``step`` (its edge, for its information) or by the odometry step between the poses."""
        pose = np.asarray(pose, dtype=float)
        node = self.num_nodes
        self.poses.append(pose)
        self._pose3.append(pose3(pose))
        self._touching.append([])
        if node == 0:
            return node
        relative = np.linalg.inv(self.poses[-2]) @ pose
        step = step if step is not None else Edge(node - 1, node, relative)
        if (step.i, step.j) != (node - 1, node):
            raise SlamError(
                f"the odometry step of node {node} must join nodes {node - 1} and {node}, got {step.i}-{step.j}"
            )
        information = self._add(step, loop=False)
        back = adjoint(np.linalg.inv(relative))  # compound the chain since the anchor by one step
        self._chain = back @ self._chain @ back.T + np.linalg.inv(swap_blocks(information))
        return node

    def add_edge(self, edge: Edge, *, loop: bool = False) -> None:
        """An edge back (``loop=False``) or a loop edge between existing nodes."""
        for k in (edge.i, edge.j):
            if not 0 <= k < self.num_nodes:
                raise SlamError(f"edge {edge.i}-{edge.j}: node {k} is not in the graph ({self.num_nodes} nodes)")
        self._add(edge, loop=loop)
        self._due |= loop  # a loop shrinks the relative covariances: compute them again at the next query

    def add_fix(self, node: int, position, sigmas) -> None:
        """A GNSS fix of ``node``: its position (map frame, m) and the fix's x y z sigmas (m)."""
        if not 0 <= node < self.num_nodes:
            raise SlamError(f"a GNSS fix of node {node}, which is not in the graph ({self.num_nodes} nodes)")
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))
        self._fixes[int(node)] = gtsam.GPSFactor(int(node), np.asarray(position, dtype=float), noise)

    def position_covariances(self, nodes, wanted=None) -> np.ndarray:
        """(K, 3, 3) covariance (m², map frame) of where each of ``nodes`` lies
        relative to the current (newest) node: how far the odometry's offset
        between them may be off. NaN for a node outside the window (see the
        module's docstring).

        ``wanted``: (K, 3, 3) covariances -> (K,) bool, the nodes whose answer
        matters (the gate's candidates; a NaN answer is never wanted). Given
        it, a node left out keeps the answer carried over from an earlier
        computation, wider than or equal to the exact one (edges added since
        only shrink it), so a gate that refuses it under that answer refuses
        it under the exact one too; only the wanted nodes are computed anew
        (each costs a marginal). If the window wants none of them while some
        lie outside it, the whole graph is computed. Without ``wanted``, every
        node is answered from the whole graph."""
        start = time.perf_counter()
        nodes = np.asarray(nodes, dtype=int).ravel()
        current = self.num_nodes - 1
        if nodes.size and not (0 <= nodes.min() and nodes.max() <= current):
            raise SlamError(f"nodes {nodes.min()} .. {nodes.max()} are not all in the graph ({self.num_nodes} nodes)")
        stale = self._due or self._anchor is None or current - self._anchor >= self.refresh_nodes
        if stale or (nodes.size and nodes.max() > self._anchor):
            self._refresh(current, whole=wanted is None)
        covariance = self._answers(nodes, wanted)
        outside = ~self._window[nodes]
        if outside.any() and (wanted is None or not wanted(covariance).any()):
            self._refresh(current, whole=True)
            covariance = self._answers(nodes, wanted)
        self.seconds += time.perf_counter() - start
        self.answers += 1
        return covariance

    def _answers(self, nodes: np.ndarray, wanted) -> np.ndarray:
        """Carried or exact answers for the window's ``nodes`` (exact for the wanted ones), NaN outside it."""
        inside = self._window[nodes]
        covariance = np.full((len(nodes), 3, 3), np.nan)
        covariance[inside] = self._from_cache(nodes[inside])
        if wanted is not None:
            redo = [k for k in np.flatnonzero(wanted(covariance) & inside) if nodes[k] not in self._exact]
        else:
            redo = [k for k in np.flatnonzero(inside) if nodes[k] not in self._exact]
        for k in redo:
            self._cached[int(nodes[k])] = self._tree.marginalCovariance(int(nodes[k]))
            self._exact.add(int(nodes[k]))
        if redo:
            covariance[redo] = self._from_cache(nodes[redo])
        return covariance

    def positions(self, nodes) -> np.ndarray:
        """(K, 3) where the graph puts each of ``nodes`` (map frame), held at
        the anchor's odometry pose and so comparable with the current node's
        odometry position: the odometry's positions moved by the loop edges
        (call after :meth:`position_covariances`, which computes them; NaN
        outside the window)."""
        return self._solved[np.asarray(nodes, dtype=int).ravel(), :3, 3]

    def solved_poses(self, nodes) -> np.ndarray:
        """(K, 4, 4) the whole poses of ``nodes`` where the graph puts them, as :meth:`positions` (NaN
        outside the window)."""
        return self._solved[np.asarray(nodes, dtype=int).ravel()]

    def _from_cache(self, nodes: np.ndarray) -> np.ndarray:
        """The position covariances of ``nodes`` relative to the current node, from the cached answers relative
        to the anchor and the chain since it (a node never computed is computed now)."""
        for c in nodes:
            if int(c) not in self._cached:
                self._cached[int(c)] = self._tree.marginalCovariance(int(c))
                self._exact.add(int(c))
        relative = np.array([self._cached[int(c)] for c in nodes]).reshape(-1, 6, 6)
        relative = relative + self._spread(nodes)
        rotation = np.array([self._about(c)[:3, :3] for c in nodes]).reshape(-1, 3, 3)
        return rotation @ relative[:, 3:, 3:] @ np.swapaxes(rotation, 1, 2)

    def _spread(self, nodes: np.ndarray) -> np.ndarray:
        """(K, 6, 6): the chain since the anchor, moved into each node's frame."""
        poses = np.array([self._about(c) for c in nodes]).reshape(-1, 4, 4)
        spread = adjoint(np.linalg.inv(poses) @ self.poses[-1])
        return spread @ self._chain @ np.swapaxes(spread, 1, 2)

    def _about(self, node) -> np.ndarray:
        """The pose node ``node``'s cached covariance is about, in the anchor's frame: where the graph was
        linearised (where the fixes put it, or its odometry pose: nodes added since, or no fixes)."""
        return self._linear[node] if node < len(self._linear) else self.poses[node]

    def _add(self, edge: Edge, *, loop: bool) -> np.ndarray:
        information = edge_information(edge, self.settings, loop=loop)
        for k in (edge.i, edge.j):
            self._touching[k].append(len(self._factors))
        self._factors.append(gtsam.BetweenFactorPose3(edge.i, edge.j, pose3(edge.relative), gaussian(information)))
        self._ends.append((min(edge.i, edge.j), max(edge.i, edge.j)))
        return information

    def _refresh(self, anchor: int, whole: bool = False) -> None:
        """The marginals of the window around node ``anchor`` (the whole graph
        if ``whole``), held at it; every cached answer is carried over to it
        (relative to the new anchor, through the chain since the old one)
        until a query wants it anew."""
        window = window_of(anchor, self.num_nodes if whole else self.window_nodes, self._touching, self._ends)
        inside = np.zeros(self.num_nodes, dtype=bool)
        inside[window] = True
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for node in window:
            values.insert(int(node), self._pose3[node])
            for f in self._touching[node]:
                i, j = self._ends[f]
                if j == node and inside[i]:  # each edge once, at its later end
                    graph.add(self._factors[f])
        fixed = [self._fixes[int(node)] for node in window if int(node) in self._fixes]
        held = len(fixed) >= MIN_FIXES  # the fixes, not the anchor's odometry pose, place the window
        to_anchor = np.eye(4)  # from the frame the graph is solved in to the one where the anchor is at its odometry
        if held:
            values = held_solve(graph, values, window, anchor, fixed, self._held, self._pose3)
            to_anchor = self.poses[anchor] @ np.linalg.inv(values.atPose3(anchor).matrix())
            for factor in fixed:
                graph.add(factor)
        noise = gtsam.noiseModel.Isotropic.Sigma(6, ANCHOR_SIGMA)
        graph.add(gtsam.PriorFactorPose3(anchor, values.atPose3(anchor), noise))
        try:
            self._tree = graph.linearize(values).eliminateMultifrontal()
            moved = values.retract(self._tree.optimize())
        except RuntimeError as exc:  # an indeterminant system: some node joined by no edge
            raise SlamError(f"the loop search's graph cannot be solved: {exc}") from None
        kept = np.array([c for c in self._cached if c < anchor], dtype=int)  # outside the window too: still valid
        carried = np.array([self._cached[c] for c in kept]).reshape(-1, 6, 6) + self._spread(kept)
        self._cached = dict(zip(kept.tolist(), carried, strict=True))
        self._solved = np.full((self.num_nodes, 4, 4), np.nan)
        self._solved[window] = to_anchor @ matrices(moved)
        self._linear = np.zeros((0, 4, 4))  # no fixes: linearised at the odometry poses (see _about)
        if held:
            self._linear = np.array(self.poses)
            self._linear[window] = to_anchor @ matrices(values)
        self._anchor, self._exact, self._chain, self._due = anchor, set(), np.zeros((6, 6)), False
        self._window = inside
        self.refreshes += 1
        self.whole += whole and self.num_nodes > self.window_nodes
