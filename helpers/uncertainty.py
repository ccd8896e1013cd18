"""How sure the pose graph is of where the current scan lies relative to an
old place, and the loop search's gate built on it (issue 21, item 5).

:class:`RelativeUncertainty` keeps the graph as the run grows it: one node
per accepted scan at its odometry pose, the odometry steps, the edges back
and the loop edges, each with its noise (:func:`edge_information`). It
answers two questions: where the graph puts an old node ``c`` relative to the
current one (the odometry's offset, moved by the loop edges found), and how
uncertain that offset is (its covariance). A loop query turns them into a
gate (:func:`mahalanobis_gate`): an old submap is searched when its centre
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

The graph is linearised at the odometry poses (they never change during a
run). Loop edges enter it as plain Gaussians: a false loop would move the old
places near it and narrow the gate around the wrong spot.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np

from .config import PoseGraphConfig
from .errors import SlamError
from .factors import Edge, edge_information, gaussian, pose3

REFRESH_NODES = 12  # recompute the marginals once the chain since the last computation holds this many nodes
ANCHOR_SIGMA = 1e-6  # the prior holding the anchor node: far stiffer than any edge, still well conditioned


def adjoint(T: np.ndarray) -> np.ndarray:
    """GTSAM's adjoint of ``T`` (..., 4, 4), rotation first: ``[[R, 0], [t^ R, R]]``."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    skew = np.zeros(t.shape[:-1] + (3, 3))
    skew[..., 0, 1], skew[..., 0, 2], skew[..., 1, 2] = -t[..., 2], t[..., 1], -t[..., 0]
    skew = skew - np.swapaxes(skew, -1, -2)
    out = np.zeros(T.shape[:-2] + (6, 6))
    out[..., :3, :3] = out[..., 3:, 3:] = R
    out[..., 3:, :3] = skew @ R
    return out


class RelativeUncertainty:
    """The run's pose graph for two questions: where does it put an old node
    relative to the current one, and how uncertain is that offset (see the
    module's docstring)::

        graph = RelativeUncertainty(config.pose_graph)
        graph.add_node(pose)  # each accepted scan, in order (odometry step from the previous one)
        graph.add_edge(edge)  # an edge back; graph.add_edge(loop, loop=True) for a loop edge
        cov = graph.position_covariances(old_nodes)  # (K, 3, 3), map frame, m²
        where = graph.positions(old_nodes)  # (K, 3), map frame, beside the current node's odometry position

    ``seconds``, ``refreshes`` and ``answers`` say what the answers cost.
    """

    def __init__(self, settings: PoseGraphConfig, refresh_nodes: int = REFRESH_NODES) -> None:
        self.settings, self.refresh_nodes = settings, refresh_nodes
        self.graph = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.poses: list[np.ndarray] = []
        self.seconds, self.refreshes, self.answers = 0.0, 0, 0  # time spent, eliminations, queries answered
        self._anchor: int | None = None  # the node the cached marginals are relative to
        self._tree = None  # the graph held at the anchor, eliminated: its marginals and its solution
        self._positions = np.zeros((0, 3))  # where the graph held at the anchor puts each node (map frame)
        self._cached: dict[int, np.ndarray] = {}  # node -> its 6 x 6 covariance relative to the anchor
        self._exact: set[int] = set()  # the nodes whose cached covariance came from the anchor's marginals
        self._chain = np.zeros((6, 6))  # the current node relative to the anchor, along the odometry steps
        self._due = False  # a loop edge came since the anchor's marginals

    @property
    def num_nodes(self) -> int:
        return len(self.poses)

    def add_node(self, pose: np.ndarray, step: Edge | None = None) -> int:
        """Node ``num_nodes`` at its odometry pose, joined to the previous one by
        ``step`` (its edge, for its information) or by the odometry step between the poses."""
        pose = np.asarray(pose, dtype=float)
        node = self.num_nodes
        self.poses.append(pose)
        self.values.insert(node, pose3(pose))
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
        self._chain = back @ self._chain @ back.T + np.linalg.inv(_rotation_first(information))
        return node

    def add_edge(self, edge: Edge, *, loop: bool = False) -> None:
        """An edge back (``loop=False``) or a loop edge between existing nodes."""
        for k in (edge.i, edge.j):
            if not 0 <= k < self.num_nodes:
                raise SlamError(f"edge {edge.i}-{edge.j}: node {k} is not in the graph ({self.num_nodes} nodes)")
        self._add(edge, loop=loop)
        self._due |= loop  # a loop shrinks the relative covariances: compute them again at the next query

    def position_covariances(self, nodes, wanted=None) -> np.ndarray:
        """(K, 3, 3) covariance (m², map frame) of where each of ``nodes`` lies
        relative to the current (newest) node: how far the odometry's offset
        between them may be off.

        ``wanted``: (K, 3, 3) covariances -> (K,) bool, the nodes whose answer
        matters (the gate's candidates). Given it, a node left out keeps the
        answer carried over from an earlier computation, wider than or equal
        to the exact one (edges added since only shrink it), so a gate that
        refuses it under that answer refuses it under the exact one too; only
        the wanted nodes are computed anew (each costs a marginal)."""
        start = time.perf_counter()
        nodes = np.asarray(nodes, dtype=int).ravel()
        current = self.num_nodes - 1
        if nodes.size and not (0 <= nodes.min() and nodes.max() <= current):
            raise SlamError(f"nodes {nodes.min()} .. {nodes.max()} are not all in the graph ({self.num_nodes} nodes)")
        stale = self._due or self._anchor is None or current - self._anchor >= self.refresh_nodes
        if stale or (nodes.size and nodes.max() > self._anchor):
            self._refresh(current)
        covariance = self._from_cache(nodes)
        if wanted is not None:
            redo = [k for k in np.flatnonzero(wanted(covariance)) if nodes[k] not in self._exact]
        else:
            redo = [k for k, c in enumerate(nodes) if c not in self._exact]
        for k in redo:
            self._cached[int(nodes[k])] = self._tree.marginalCovariance(int(nodes[k]))
            self._exact.add(int(nodes[k]))
        if redo:
            covariance[redo] = self._from_cache(nodes[redo])
        self.seconds += time.perf_counter() - start
        self.answers += 1
        return covariance

    def positions(self, nodes) -> np.ndarray:
        """(K, 3) where the graph puts each of ``nodes`` (map frame), held at
        the anchor's odometry pose and so comparable with the current node's
        odometry position: the odometry's positions moved by the loop edges
        (call after :meth:`position_covariances`, which computes them)."""
        return self._positions[np.asarray(nodes, dtype=int).ravel()]

    def _from_cache(self, nodes: np.ndarray) -> np.ndarray:
        """The position covariances of ``nodes`` relative to the current node, from the cached answers relative
        to the anchor and the chain since it (a node never computed is computed now)."""
        for c in nodes:
            if int(c) not in self._cached:
                self._cached[int(c)] = self._tree.marginalCovariance(int(c))
                self._exact.add(int(c))
        relative = np.array([self._cached[int(c)] for c in nodes]).reshape(-1, 6, 6)
        relative = relative + self._spread(nodes)
        rotation = np.array([self.poses[c][:3, :3] for c in nodes]).reshape(-1, 3, 3)
        return rotation @ relative[:, 3:, 3:] @ np.swapaxes(rotation, 1, 2)

    def _spread(self, nodes: np.ndarray) -> np.ndarray:
        """(K, 6, 6): the chain since the anchor, moved into each node's frame."""
        poses = np.array([self.poses[c] for c in nodes]).reshape(-1, 4, 4)
        spread = adjoint(np.linalg.inv(poses) @ self.poses[-1])
        return spread @ self._chain @ np.swapaxes(spread, 1, 2)

    def _add(self, edge: Edge, *, loop: bool) -> np.ndarray:
        information = edge_information(edge, self.settings, loop=loop)
        self.graph.add(gtsam.BetweenFactorPose3(edge.i, edge.j, pose3(edge.relative), gaussian(information)))
        return information

    def _refresh(self, anchor: int) -> None:
        """The marginals of the graph held at node ``anchor``; every cached
        answer is carried over to it (relative to the new anchor, through the
        chain since the old one) until a query wants it anew."""
        graph = gtsam.NonlinearFactorGraph(self.graph)
        noise = gtsam.noiseModel.Isotropic.Sigma(6, ANCHOR_SIGMA)
        graph.add(gtsam.PriorFactorPose3(anchor, self.values.atPose3(anchor), noise))
        try:
            self._tree = graph.linearize(self.values).eliminateMultifrontal()
            moved = self.values.retract(self._tree.optimize())
        except RuntimeError as exc:  # an indeterminant system: some node joined by no edge
            raise SlamError(f"the loop search's graph cannot be solved: {exc}") from None
        self._positions = gtsam.utilities.extractPose3(moved)[:, 9:12]  # rows [R (9), t (3)], node by node
        kept = np.array([c for c in self._cached if c < anchor], dtype=int)
        carried = np.array([self._cached[c] for c in kept]).reshape(-1, 6, 6) + self._spread(kept)
        self._cached = dict(zip(kept.tolist(), carried, strict=True))
        self._anchor, self._exact, self._chain, self._due = anchor, set(), np.zeros((6, 6)), False
        self.refreshes += 1


def _rotation_first(information: np.ndarray) -> np.ndarray:
    order = np.array([3, 4, 5, 0, 1, 2])
    return information[np.ix_(order, order)]


def mahalanobis_gate(
    centres: np.ndarray, position: np.ndarray, covariances: np.ndarray, radius, sigmas: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which old places the scan at ``position`` may truly be over, and the
    search radius around each.

    Place ``k`` (its centre, map frame) is in reach when the offset to it,
    less ``radius`` (the place's extent, m; one number or one per place), is within
    ``sigmas`` of its uncertainty: ``d' = d (1 - radius / |d|)`` and
    ``d'^T C^-1 d' < sigmas^2`` with ``C = covariances[k]``. The radius along
    the direction ``u`` of the offset follows: ``radius + sigmas /
    sqrt(u^T C^-1 u)``, so that the gate is ``|d| < that radius``; with
    ``C = 0`` it is ``radius``. Returns (in reach (K,) bool, radius (K,) m).
    """
    offset = np.asarray(centres, float).reshape(-1, 3) - np.asarray(position, float)
    distance = np.linalg.norm(offset, axis=1)
    direction = offset / np.maximum(distance, 1e-12)[:, None]
    covariances = np.asarray(covariances, float).reshape(-1, 3, 3)
    floor = 1e-12 * np.eye(3)  # a node at the anchor has no uncertainty at all
    inverse = np.linalg.inv(covariances + floor)
    spread = 1.0 / np.sqrt(np.einsum("ki,kij,kj->k", direction, inverse, direction))
    reach = np.asarray(radius, float) + sigmas * spread
    return distance < reach, reach
