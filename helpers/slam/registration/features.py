"""Stage 3a: downsampling, FPFH descriptors and descriptor matching (the
reference's ``pcdownsample``, ``extractFPFHFeatures`` and ``pcmatchfeatures``).

Descriptor normalisation, used everywhere in this package: Open3D's FPFH is
three 11-bin histograms (in Open3D's order: angles theta, alpha, phi) that each sum to 200.
:func:`fpfh` divides each histogram by its own sum, so that every bin is a
fraction, then scales the whole 33-vector to unit Euclidean length. The
*normalised distance* between two descriptors ``a`` and ``b`` is then
``|a - b| / sqrt(2)``: 0 for identical descriptors and at most 1 (two unit
vectors with no negative entries are at most ``sqrt(2)`` apart), which is the
scale ``match_threshold`` is expressed in.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d

from helpers.errors import SlamError
from helpers.geometry import check_points

HISTOGRAMS = 3  # FPFH is three histograms ...
BINS = 11  # ... of 11 bins each
UP = np.array([0.0, 0.0, 1.0])  # normals are turned towards the sensor, which looks down from +z


def grid_average(points, step: float) -> np.ndarray:
    """Replace the points of every cubic cell of side ``step`` (m) by their mean.

    Cells are those of a grid anchored at the origin; the result has one point
    per occupied cell, ordered by cell index (x, then y, then z), so the same
    input always gives the same output in the same order.
    """
    points = check_points(points, "the cloud to downsample")
    if not (np.isfinite(step) and step > 0):
        raise SlamError(f"the grid step must be a positive number of metres, got {step!r}")
    cells = np.floor(points / step).astype(np.int64)
    cells -= cells.min(axis=0)
    extent = cells.max(axis=0) + 1
    key = (cells[:, 0] * extent[1] + cells[:, 1]) * extent[2] + cells[:, 2]
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    sums = np.column_stack([np.bincount(inverse, weights=points[:, i]) for i in range(3)])
    return sums / counts[:, None]


def to_cloud(points: np.ndarray, normals_knn: int | None = None) -> o3d.geometry.PointCloud:
    """An Open3D cloud of ``points``; with ``normals_knn``, with normals from
    that many neighbours, turned towards +z (the sensor is above the ground)."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if normals_knn is not None:
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(normals_knn))
        cloud.orient_normals_to_align_with_direction(UP)
    return cloud


def fpfh(points, neighbors: int) -> np.ndarray:
    """FPFH descriptors, (M, 33), one per point, normalised as the module says.

    Normals come from the ``neighbors`` nearest points and point up (+z); the
    histograms use the same ``neighbors`` nearest points.
    :func:`keypoint_fpfh` describes only some of the points.
    """
    return keypoint_fpfh(points, neighbors, 1.0)[1]


def keypoint_fpfh(points, neighbors: int, share: float) -> tuple[np.ndarray, np.ndarray]:
    """The :func:`keypoints` of a cloud (indices, ascending) and their
    :func:`fpfh` descriptors, (K, 33): the descriptors of the other points
    are never computed.

    Open3D's tensor FPFH is used: on the same normals it gives the legacy
    ``compute_fpfh_feature``'s descriptors exactly, and it can skip the
    points that are not keypoints. Either is the largest part
    of a scan's preparation; a numpy version sharing one neighbour query
    between normals, SPFH and FPFH reproduced them but was slower
    (``benchmarks/README.md``).
    """
    points = check_points(points, "the cloud to describe")
    if neighbors < 3:
        raise SlamError(f"FPFH needs at least 3 neighbours, got {neighbors}")
    if len(points) <= neighbors:
        raise SlamError(
            f"FPFH with {neighbors} neighbours needs more than {neighbors} points, the cloud has {len(points)}"
        )
    cloud = o3d.t.geometry.PointCloud(o3d.core.Tensor(points))
    cloud.estimate_normals(max_nn=neighbors)
    cloud.orient_normals_to_align_with_direction(o3d.core.Tensor(UP))
    chosen = keypoints(cloud.point.normals.numpy(), share)
    indices = None if len(chosen) == len(points) else o3d.core.Tensor(chosen)
    raw = o3d.t.pipelines.registration.compute_fpfh_feature(cloud, max_nn=neighbors, indices=indices)
    return chosen, normalise_descriptors(raw.numpy())


def keypoints(normals, share: float) -> np.ndarray:
    """Indices, ascending, of the ``share`` of points whose surface is most
    tilted (largest ``1 - |n_z|``; ties keep the lower index); every index
    when ``share`` is 1.

    Why tilted: seen from 700 m up, flat ground and flat roofs have nearly
    the same descriptor everywhere, so their matches are mostly wrong or
    dropped by the ratio test. Matching only the more tilted part of each
    scan (roof slopes, walls, tree crowns) gives fewer matches, more of them
    right, in a fraction of the matching time (it compares every moving
    descriptor with every fixed one) and the same odometry after ICP; but
    the robust fit, with fewer inliers, lands a little farther from the
    truth, so the reference's "every point" stays the default (``benchmarks/README.md``).
    """
    normals = np.asarray(normals, dtype=np.float64)
    if not 0 < share <= 1:
        raise SlamError(f"the keypoint share must lie in (0, 1], got {share!r}")
    if share == 1:
        return np.arange(len(normals))
    count = max(1, round(share * len(normals)))
    tilt = 1.0 - np.abs(normals[:, 2])
    return np.sort(np.argsort(-tilt, kind="stable")[:count])


def normalise_descriptors(raw: np.ndarray) -> np.ndarray:
    """Each 11-bin histogram divided by its sum, then each 33-vector scaled to unit length."""
    hist = np.asarray(raw, dtype=np.float64).reshape(len(raw), HISTOGRAMS, BINS)
    sums = hist.sum(axis=2, keepdims=True)
    hist = np.divide(hist, sums, out=np.zeros_like(hist), where=sums > 0)
    flat = hist.reshape(len(raw), HISTOGRAMS * BINS)
    norms = np.linalg.norm(flat, axis=1, keepdims=True)
    return np.divide(flat, norms, out=np.zeros_like(flat), where=norms > 0)
