"""Our odometry against its peers on the same scans, in one run: ms per accepted scan and ATE.

    .venv/bin/python benchmarks/bench_peers.py [--scans N]

Every system registers the default flight's accepted scans (every
``skip_frames``-th) one after the other and chains the motions from the
first true pose; the ATE is taken against the true poses of those scans.

- ours, global: the reference's workflow (FPFH, matching, robust fit, ICP) for every scan;
- ours, global, keypoints 0.5: the same, describing and matching the more tilted half of each scan;
- ours, tracking: ICP from the last motion, the global workflow when a check fails;
- Open3D's recipe: its global-registration tutorial on 1.5 m voxels (FPFH,
  RANSAC on feature matches), refined by its generalized ICP;
- small_gicp: GICP on 0.75 m voxels from a constant-velocity guess;
- KISS-ICP (``pip install ".[bench]"``): its own pipeline, given the aerial ranges.

A peer that is not installed is reported as missing, not as a failure.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import helpers
from helpers.config import Config
from helpers.metrics import ate
from helpers.odometry import run_odometry

VOXEL = 1.5  # m, Open3D's recipe (the reference's gridStep)


def ours(mode: str, keypoint_share: float = 1.0):
    def run(scans, first_pose):
        config = Config().with_values(
            features=dict(keypoint_share=keypoint_share), registration=dict(mode=mode, skip_frames=1)
        )
        return run_odometry(scans, first_pose, config).poses

    return run


def open3d_recipe(scans, first_pose):
    import open3d as o3d

    reg = o3d.pipelines.registration

    def prepare(points):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(VOXEL)
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * VOXEL, max_nn=30))
        feature = reg.compute_fpfh_feature(cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * VOXEL, max_nn=100))
        return cloud, feature

    o3d.utility.random.seed(0)
    poses, previous = [first_pose], prepare(scans[0])
    for points in scans[1:]:
        current = prepare(points)
        coarse = reg.registration_ransac_based_on_feature_matching(
            current[0],
            previous[0],
            current[1],
            previous[1],
            True,
            1.5 * VOXEL,
            reg.TransformationEstimationPointToPoint(False),
            3,
            [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(1.5 * VOXEL)],
            reg.RANSACConvergenceCriteria(100000, 0.999),
        )
        fine = reg.registration_generalized_icp(
            current[0], previous[0], VOXEL, coarse.transformation, reg.TransformationEstimationForGeneralizedICP()
        )
        poses.append(poses[-1] @ np.asarray(fine.transformation))
        previous = current
    return np.array(poses)


def small_gicp_odometry(scans, first_pose):
    import small_gicp

    from helpers.icp import threads

    poses, motion = [first_pose], np.eye(4)
    previous = small_gicp.preprocess_points(scans[0], 0.75, num_threads=threads())
    for points in scans[1:]:
        current = small_gicp.preprocess_points(points, 0.75, num_threads=threads())
        result = small_gicp.align(previous[0], current[0], previous[1], motion, num_threads=threads())
        motion = result.T_target_source
        poses.append(poses[-1] @ motion)
        previous = current
    return np.array(poses)


def kiss_icp_odometry(scans, first_pose):
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    config = KISSConfig()
    config.data.max_range, config.data.deskew, config.mapping.voxel_size = 1000.0, False, VOXEL
    odometry = KissICP(config)
    poses = []
    for points in scans:
        odometry.register_frame(points, np.zeros(len(points)))
        poses.append(first_pose @ odometry.last_pose)
    return np.array(poses)


PEERS = {
    "ours, global (the reference)": (ours("global"), None),
    "ours, global, keypoints 0.5": (ours("global", 0.5), None),
    "ours, tracking": (ours("tracking"), None),
    "Open3D's recipe": (open3d_recipe, "open3d"),
    "small_gicp odometry": (small_gicp_odometry, "small_gicp"),
    "KISS-ICP": (kiss_icp_odometry, "kiss_icp"),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=None, help="accepted scans to register (default: all)")
    args = parser.parse_args()
    data = helpers.create_dataset()
    indices = np.arange(0, len(data), Config().registration.skip_frames)[: args.scans]
    scans, truth = [data.scans[i] for i in indices], data.poses[indices]
    print(f"{len(indices)} accepted scans of the default flight ({len(data)} scans)", flush=True)
    rows = []
    for name, (run, module) in PEERS.items():
        if module is not None:
            try:
                __import__(module)
            except ImportError:
                print(f"{name:<30} missing: pip install '.[bench]'")
                continue
        start = time.perf_counter()
        poses = run(scans, truth[0])
        ms = 1000 * (time.perf_counter() - start) / (len(scans) - 1)
        rows.append((name, ms, ate(poses, truth).rmse))
        print(f"{name:<30} {ms:8.1f} ms per scan, ATE {rows[-1][2]:.2f} m", flush=True)
    reference = rows[0][1]
    print(f"{'system':<30} {'ms/scan':>8} {'x ours':>7} {'ATE m':>7}")
    for name, ms, error in rows:
        print(f"{name:<30} {ms:8.1f} {ms / reference:7.2f} {error:7.2f}")


if __name__ == "__main__":
    main()
