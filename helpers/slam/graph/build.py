"""The pose graph of a run, built from its edges: the odometry's steps, the edges back and the loop edges,
each weighed as ``[pose_graph] graph_weights`` says, with the motion factor when asked."""

from __future__ import annotations

from helpers.config.tables import Config
from helpers.slam.graph.factors import Edge, edge_information, motion_factors
from helpers.slam.graph.optimizer import PoseGraph


def build_pose_graph(odometry, extra: list[Edge], loops, config: Config) -> PoseGraph:
    """The pose graph of a run (``odometry``: its :class:`~helpers.slam.odometry.OdometryResult`): the
    first node at the first odometry pose, an
    edge per odometry step, the ``extra`` edges that skip nodes and the
    ``loops`` (anything with ``i``, ``j`` and ``relative``) as loop edges.

    With ``graph_weights = "icp"`` every registration gets the sigmas of
    ``[pose_graph] edge_sigma_m`` and ``edge_sigma_deg``, times the number of
    steps an edge spans: an edge to the scan ``k`` nodes back is measured on a
    smaller overlap and is less sure (notebook 6 measures how much). With
    ``"hessian"`` every edge carries its own calibrated information (each
    registration's, :mod:`helpers.slam.graph.information`), an edge back's divided by the
    steps it spans: the Hessian sees the noise of the pairs, not the error of
    a smaller overlap that grows with the span (``benchmarks/bench_information.py``
    measures both). An edge without information (an odometry given without
    it, point-to-point ICP) falls back to the icp sigmas.
    """
    settings = config.pose_graph
    steps = odometry.information
    steps = steps if len(steps) == len(odometry.relative) else [None] * len(odometry.relative)
    graph = PoseGraph()
    pose = odometry.poses[0]
    graph.add_node(pose)
    for step, information in zip(odometry.relative, steps, strict=True):
        pose = pose @ step
        j = graph.add_node(pose)
        edge = Edge(j - 1, j, step, information=information)
        graph.add_odometry(j - 1, j, step, information=edge_information(edge, settings))
    for edge in extra:
        graph.add_odometry(edge.i, edge.j, edge.relative, information=edge_information(edge, settings))
    for loop in loops:
        graph.add_loop(loop.i, loop.j, loop.relative, edge_information(loop, settings, loop=True))
    if config.pose_graph.motion_factor:
        for factor in motion_factors(odometry.relative, config.pose_graph):
            graph.add_factor(factor)
    return graph
