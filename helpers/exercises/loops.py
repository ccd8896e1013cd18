"""Checks for the exercises of notebook 5 (loop closure).

Each check reads the truth from the run it is given (the loop search's
graph, the simulator's true poses) and prints one line.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from helpers.errors import SlamError
from helpers.exercises.report import report, unanswered
from helpers.quality.evaluation import loop_error
from helpers.quality.metrics import FALSE_LOOP_DEG, FALSE_LOOP_M, is_false_loop
from helpers.slam.graph.factors import Edge
from helpers.slam.loops.search import distance_flown_since, mahalanobis_gate, radius_after
from helpers.slam.loops.uncertainty import RelativeUncertainty
from helpers.slam.registration.icp import icp_rmse
from helpers.slam.registration.icp_service import surface_rmse
from helpers.slam.submaps import centre_scan_id


def search_graph(result, node: int) -> RelativeUncertainty:
    """The loop search's graph (:class:`helpers.slam.loops.uncertainty.RelativeUncertainty`)
    as it stood when ``node`` ran its query: the odometry poses and steps (with
    their information) of nodes 0 .. ``node``, the edges back of the earlier nodes and the loop edges
    they closed (a node's own edges back come after its query)."""
    graph, poses = RelativeUncertainty(result.config.pose_graph), result.poses_odometry
    information = list(result.odometry.information) or [None] * (len(poses) - 1)
    graph.add_node(poses[0])
    for k in range(1, node + 1):
        relative = np.linalg.inv(poses[k - 1]) @ poses[k]
        graph.add_node(poses[k], Edge(k - 1, k, relative, information=information[k - 1]))
    for edge in result.extra_edges:
        if edge.j < node:
            graph.add_edge(edge)
    for edge in result.loops:
        if edge.j < node:
            graph.add_edge(edge, loop=True)
    return graph


def _gate_radius(result, node: int, submap_id: int) -> float:
    """The search radius (m) around submap ``submap_id`` for the query of
    ``node`` under the run's search: with ``search = "growth"``,
    :func:`helpers.slam.loops.search.radius_after` the path flown since the submap;
    with ``"uncertainty"``, the gate of :func:`helpers.slam.loops.search.mahalanobis_gate`
    with the exact covariance (``gtsam.Marginals``) of the graph of
    :func:`search_graph` held at ``node``. The run itself may reuse a
    covariance computed a few nodes earlier, which errs on the wide side, so
    the radius it recorded (``LoopQuery.radius``) is at least this one."""
    settings, n = result.config.loop_closure, result.config.map.n_scans_per_submap
    position = result.poses_odometry[node][:3, 3]
    if settings.search == "growth":
        count = (node + 1) // n
        return float(radius_after(distance_flown_since(result.submaps.centres[:count], position)[submap_id], settings))
    centre = centre_scan_id(submap_id, n)
    graph = search_graph(result, node)
    covariance = graph.position_covariances([centre])[0]
    scans = result.poses_odometry[submap_id * n : (submap_id + 1) * n, :3, 3]
    extent = np.linalg.norm(scans - result.poses_odometry[centre][:3, 3], axis=1).max()
    radius = settings.loop_closure_search_radius + extent
    _, reach = mahalanobis_gate(graph.positions([centre]), position, covariance, radius, settings.search_sigmas)
    return float(reach[0])


def check_search_radius(result, node: int, submap_id: int, radius) -> bool:
    """Exercise 5.1: the search radius (m) around submap ``submap_id`` in the
    loop query of ``node`` (:func:`_gate_radius`)."""
    if unanswered(radius):
        return report(False, "", "fill in the radius, in metres")
    if not any(q.node == node for q in result.queries):
        raise SlamError(f"node {node} ran no loop query that registered a submap: choose a node of result.queries")
    truth = _gate_radius(result, node, submap_id)
    base = result.config.loop_closure.loop_closure_search_radius
    if abs(float(radius) - truth) < 0.05:
        times = "more than twice" if truth > 2 * base else "more than"
        return report(True, f"the search around submap {submap_id} reached {times} the fixed {base:g} m", "")
    if result.config.loop_closure.search == "growth":
        hint = (
            "add up the path from the submap's centre through every later centre to the drone's odometry position, "
            "then r = loop_closure_search_radius + loop_search_growth * that distance"
        )
    else:
        hint = (
            "r = loop_closure_search_radius + the submap's extent, C the centre's position covariance, u the unit "
            "offset from the drone to the centre: radius = r + search_sigmas / sqrt(u^T C^-1 u)"
        )
    return report(False, "", hint)


def check_row_slip(result, dataset, edge, is_false, rmse, accepted) -> bool:
    """Exercise 5.2: a loop ``edge`` of ``result`` moved off its match: whether it is false by the truth
    (:func:`helpers.quality.metrics.is_false_loop`), the score the run gives it (the surface RMSE of the
    scan of node ``j`` where the edge puts it over the old scan of node ``i``) and whether the run's
    ``rmse_threshold`` accepts it."""
    if any(unanswered(a) for a in (is_false, rmse, accepted)):
        return report(False, "", "fill in the verdict, the score and whether the threshold accepts it")
    error_m, error_deg = loop_error(dataset.poses[result.indices], edge)
    false = is_false_loop(error_m, error_deg)
    moving, fixed = result.clouds[edge.j], result.clouds[edge.i]
    inlier_distance = result.config.registration.inlier_distance
    threshold = result.config.loop_closure.rmse_threshold
    score = surface_rmse(moving, fixed, edge.relative, inlier_distance)
    if bool(is_false) != false:
        limits = f"{FALSE_LOOP_M:g} m or {FALSE_LOOP_DEG:g} deg"
        return report(False, "", f"an edge is false beyond {limits} of the truth: how far off did the shift put it?")
    if not abs(float(rmse) - score) < 0.01:
        if abs(float(rmse) - icp_rmse(moving, fixed, edge.relative, inlier_distance)) < 0.01:
            return report(False, "", "that is the point-to-point RMSE: the run scores along the normals (5.3)")
        return report(
            False,
            "",
            "the score is surface_rmse(moving, fixed, edge.relative, inlier_distance): the scan of node j "
            "where the edge puts it, over the old scan of node i",
        )
    if bool(accepted) != (score < threshold):
        return report(False, "", "a loop edge is accepted when its score is below settings.rmse_threshold")
    verdict = "a false loop edge" if false else "a right loop edge"
    if score < threshold:
        return report(True, f"{verdict}, and its score is under rmse_threshold: the threshold would accept it", "")
    return report(True, f"{verdict}, and its score is over rmse_threshold: the threshold refuses it", "")


def _fixed_radius_loops(result, end: int) -> list[int]:
    """The nodes 0 .. ``end`` of ``result`` that close a loop when the
    search radius does not grow (``loop_search_growth = 0``, the reference's
    fixed radius, queried at every scan): the pipeline's own loop closer run
    again on the run's scans and odometry poses."""
    from helpers.slam.loops.closer import LoopCloser
    from helpers.slam.registration.icp_service import IcpService

    config = result.config
    fixed = replace(config.loop_closure, loop_search_growth=0.0, search="growth", skip_after_loop=0)
    loops = LoopCloser(fixed, config.map, IcpService.from_config(config.registration))
    clouds, poses = result.clouds[: end + 1], result.poses_odometry[: end + 1]
    for node, (cloud, pose) in enumerate(zip(clouds, poses, strict=True)):
        loops.add(node, cloud, pose, clouds, poses)
    return [loop.j for loop in loops.loops]


def check_fixed_radius(result, end: int, nodes) -> bool:
    """Exercise 5.3: the nodes 0 .. ``end`` that still close a loop with the reference's fixed radius."""
    if unanswered(nodes):
        return report(False, "", "fill in the list of nodes (the j of each loop edge found)")
    truth = _fixed_radius_loops(result, end)
    answer = sorted(int(j) for j in np.asarray(nodes, int).ravel())
    if answer == sorted(truth):
        grown = {loop.j for loop in result.loops if loop.j <= end}
        if grown - set(truth):
            return report(True, "the fixed radius misses loop closures that the default search finds here", "")
        return report(True, "the fixed radius finds every loop closure of the default search here", "")
    return report(
        False,
        "",
        "run the loop of 5.4 with dataclasses.replace(growth, loop_search_growth=0.0) over nodes 0 .. end "
        "and list the node j of every loop edge it finds",
    )
