"""How sure the pose graph is of where the current scan lies relative to an
old place, and the loop search's gate built on it (issue 21, item 5).

:class:`RelativeUncertainty` keeps the graph as the run grows it: one node
per accepted scan at its odometry pose, the odometry steps, the edges back
and the loop edges, each with its noise (:func:`edge_information`). It
answers one question: the covariance of the current node's position relative
to an old node ``c``. A loop query turns that into a gate
(:func:`mahalanobis_gate`): an old submap is searched when its centre could,
within ``search_sigmas`` sigmas, lie within the fixed search radius of the
scan. With no uncertainty the gate is the reference's fixed radius; drift
widens it only where the graph says drift can be, and a loop shrinks it.

The covariance, in GTSAM's conventions (a pose ``T = T_hat @ Exp(xi)``,
``xi`` rotation first): hold node ``m`` fixed (a stiff prior on it and on no
other node) and the marginal covariance of node ``c`` (``gtsam.Marginals``)
is the covariance of ``c`` relative to ``m``. Computing it is the costly part,
so it is done at most once per query, anchored at the node that asks, and
reused while it stays valid: for the next few nodes the chain of odometry
steps since ``m`` is compounded (``Sigma <- Ad(S^-1) Sigma Ad(S^-1)^T + Q``)
and added through the adjoint. A new loop edge makes it stale (loops are what
shrink it); so does a chain grown to :data:`REFRESH_NODES` nodes. The chain
leaves out the edges back among its nodes, so the reused answer errs on the
wide side.

The graph is linearised at the odometry poses (they never change during a
run). Loop edges enter it as plain Gaussians: a false loop would make the
gate too narrow near it, never too wide.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np

from .config import PoseGraphConfig
from .errors import SlamError
from .factors import Edge, check_information, gaussian, information_from_sigmas, pose3

REFRESH_NODES = 12  # recompute the marginals once the chain since the last computation holds this many nodes
ANCHOR_SIGMA = 1e-6  # the prior holding the anchor node: far stiffer than any edge, still well conditioned


def edge_information(edge: Edge, settings: PoseGraphConfig, *, loop: bool = False) -> np.ndarray:
    """The (6, 6) translation-first information of ``edge`` in the graph.

    ``edge.information`` when the edge carries one (the registration's,
    calibrated); otherwise what :func:`helpers.slam.build_pose_graph` gives it
    today: with ``graph_weights = "icp"`` the sigmas of ``[pose_graph]``
    times the steps spanned (a loop edge: once), with ``"identity"`` the
    reference's 1 m and 1 rad.
    """
    information = getattr(edge, "information", None)
    if information is not None:
        return check_information(information)
    if settings.graph_weights != "icp":
        return np.eye(6)
    span = 1 if loop else abs(edge.j - edge.i)
    return information_from_sigmas(settings.edge_sigmas * span)


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
    """The run's pose graph for one question: how uncertain is the current
    node's position relative to an old node (see the module's docstring)::

        graph = RelativeUncertainty(config.pose_graph)
        graph.add_node(pose)  # each accepted scan, in order (odometry step from the previous one)
        graph.add_edge(edge)  # an edge back; graph.add_edge(loop, loop=True) for a loop edge
        cov = graph.position_covariances(old_nodes)  # (K, 3, 3), map frame, m²

    ``seconds`` and ``refreshes`` say what the answers cost.
    """

    def __init__(self, settings: PoseGraphConfig, refresh_nodes: int = REFRESH_NODES) -> None:
        self.settings, self.refresh_nodes = settings, refresh_nodes
        self.graph = gtsam.NonlinearFactorGraph()
        self.values = gtsam.Values()
        self.poses: list[np.ndarray] = []
        self.seconds, self.refreshes = 0.0, 0
        self._anchor: int | None = None  # the node the cached marginals are relative to
        self._marginals = None
        self._cached: dict[int, np.ndarray] = {}  # node -> its 6 x 6 covariance relative to the anchor
        self._chain = np.zeros((6, 6))  # the current node relative to the anchor, along the odometry steps

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
        if self._anchor is not None:  # compound the chain since the anchor by one step
            back = adjoint(np.linalg.inv(relative))
            covariance = np.linalg.inv(_rotation_first(information))
            self._chain = back @ self._chain @ back.T + covariance
        return node

    def add_edge(self, edge: Edge, *, loop: bool = False) -> None:
        """An edge back (``loop=False``) or a loop edge between existing nodes."""
        for k in (edge.i, edge.j):
            if not 0 <= k < self.num_nodes:
                raise SlamError(f"edge {edge.i}-{edge.j}: node {k} is not in the graph ({self.num_nodes} nodes)")
        self._add(edge, loop=loop)
        if loop:
            self._anchor = None  # a loop changes every relative covariance: compute them again

    def position_covariances(self, nodes) -> np.ndarray:
        """(K, 3, 3) covariance (m², map frame) of where each of ``nodes`` lies
        relative to the current (newest) node: how far the odometry's offset
        between them may be off."""
        start = time.perf_counter()
        nodes = np.asarray(nodes, dtype=int).ravel()
        current = self.num_nodes - 1
        if nodes.size and not (0 <= nodes.min() and nodes.max() <= current):
            raise SlamError(f"nodes {nodes.min()} .. {nodes.max()} are not all in the graph ({self.num_nodes} nodes)")
        stale = self._anchor is None or current - self._anchor >= self.refresh_nodes
        if stale or (nodes.size and nodes.max() > self._anchor):
            self._refresh(current)
        relative = np.array([self._relative(int(c)) for c in nodes]).reshape(-1, 6, 6)
        poses = np.array([self.poses[c] for c in nodes]).reshape(-1, 4, 4)
        if self._anchor != current:  # the chain since the anchor, moved into each node's frame
            spread = adjoint(np.linalg.inv(poses) @ self.poses[current])
            relative = relative + spread @ self._chain @ np.swapaxes(spread, 1, 2)
        rotation = poses[:, :3, :3]
        covariance = rotation @ relative[:, 3:, 3:] @ np.swapaxes(rotation, 1, 2)
        self.seconds += time.perf_counter() - start
        return covariance

    def _add(self, edge: Edge, *, loop: bool) -> np.ndarray:
        information = edge_information(edge, self.settings, loop=loop)
        self.graph.add(gtsam.BetweenFactorPose3(edge.i, edge.j, pose3(edge.relative), gaussian(information)))
        return information

    def _refresh(self, anchor: int) -> None:
        """The marginals of the graph held at node ``anchor``."""
        graph = gtsam.NonlinearFactorGraph(self.graph)
        noise = gtsam.noiseModel.Isotropic.Sigma(6, ANCHOR_SIGMA)
        graph.add(gtsam.PriorFactorPose3(anchor, self.values.atPose3(anchor), noise))
        try:
            self._marginals = gtsam.Marginals(graph, self.values)
        except RuntimeError as exc:  # an indeterminant system: some node joined by no edge
            raise SlamError(f"the loop search's graph cannot be solved: {exc}") from None
        self._anchor, self._cached, self._chain = anchor, {}, np.zeros((6, 6))
        self.refreshes += 1

    def _relative(self, node: int) -> np.ndarray:
        if node == self._anchor:
            return np.zeros((6, 6))
        if node not in self._cached:
            self._cached[node] = self._marginals.marginalCovariance(node)
        return self._cached[node]


def _rotation_first(information: np.ndarray) -> np.ndarray:
    order = np.array([3, 4, 5, 0, 1, 2])
    return information[np.ix_(order, order)]


def mahalanobis_gate(
    centres: np.ndarray, position: np.ndarray, covariances: np.ndarray, radius: float, sigmas: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which old places the scan at ``position`` may truly be over, and the
    search radius around each.

    Place ``k`` (its centre, map frame) is in reach when the odometry's offset
    to it, less the fixed ``radius`` (the place's extent), is within
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
    reach = radius + sigmas * spread
    return distance < reach, reach
