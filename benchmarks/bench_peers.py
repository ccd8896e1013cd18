"""Our odometry against its peers on the same scans, in one run: ms per accepted scan and ATE.

    .venv/bin/python benchmarks/bench_peers.py [--scans N] [--peers "ours, global" "Open3D" ...] [--no-kiss-matcher]

Every system registers the default flight's accepted scans (every
``skip_frames``-th) one after the other and chains the motions from the
first true pose; the ATE is taken against the true poses of those scans.

- ours, global: the reference's workflow (FPFH, matching, robust fit, ICP) for every scan, with our
  yaw-and-translation robust fit (``robust_fit = "msac4"``, the default) and the descriptor grid that
  ``python -m helpers run`` fits to this flight (3 m, twice the reference's: ``helpers.slam.flight_fit``);
- ours, global, 1.5 m grid: the same on the reference's descriptor grid (``Config()``, the notebooks');
- ours, global, rigid fit: the same with the reference's rigid fit (``robust_fit = "msac"``) and grid;
- ours, global, keypoints 0.5: describing and matching the more tilted half of each scan (1.5 m grid);
- ours, global, 2 m / 40 and 3 m / 30: other descriptor grids and fewer neighbours (issue 22's levers);
- ours, tracking: ICP from the last motion, the global workflow when a check fails;
- ours, tracking, 1 mm tolerance: the same, ICP stopping at the tolerance of earlier versions;
- Open3D's recipe: its global-registration tutorial on 1.5 m voxels (FPFH,
  RANSAC on feature matches), refined by its generalized ICP;
- small_gicp: GICP on 0.75 m voxels from a constant-velocity guess;
- KISS-ICP (``pip install ".[bench]"``): its own pipeline, given the aerial ranges.

Then KISS-Matcher (``pip install ".[bench]"``), a coarse registration peer
rather than an odometry, on the same pairs of consecutive accepted scans: its
default solver and its yaw-only one (``use_quatro=True``), each from the raw
scans on ``--kiss-voxel`` m voxels (default 1.5 m, the reference's grid, as
Open3D's recipe and our features use; its own default of 0.3 m is made for
dense ground scans). Its noise bounds are gains times the voxel and it caps
them at 1 m (so both are 1 m at 1.5 m voxels; it prints a warning when it
does). Per row: CPU ms of its ``estimate`` per pair (median / 90th pct.; it
runs TBB threads with no setting for their number, so the process is held to
one core by CPU affinity for these rows and the times are single-core CPU
time), its coarse error against the true relative pose (translation at the
sensor: median, max, pairs off by more than 1 m of all), pairs it flagged invalid,
the error after the package's ICP (the run's configuration) refines it, and
the ATE of those refined motions chained.

Each row gives wall ms and process CPU ms per scan (every thread's; on a busy machine the CPU
time is the fairer figure) and both as multiples of the first row run. A peer that is not
installed is reported as missing, not as a failure.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import helpers
from helpers.config.tables import Config
from helpers.quality.metrics import ate
from helpers.slam.flight_fit import DESCRIPTOR_GRID_FACTOR
from helpers.slam.odometry import run_odometry
from helpers.slam.preprocess import prepare as prepare_frame
from helpers.slam.registration.icp import refine_icp

VOXEL = 1.5  # m, Open3D's recipe (the reference's gridStep)


def ours(mode: str, features: dict | None = None, registration: dict | None = None):
    """Our odometry in ``mode`` with some ``[features]`` and ``[registration]`` values changed."""

    def run(scans, first_pose):
        config = Config().with_values(
            features=features or {}, registration={"mode": mode, "skip_frames": 1, **(registration or {})}
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

    from helpers.slam.registration.icp import threads

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
    "ours, global": (ours("global", {"grid_step": DESCRIPTOR_GRID_FACTOR * Config().features.grid_step}), None),
    "ours, global, 1.5 m grid": (ours("global"), None),
    "ours, global, rigid fit": (ours("global", registration={"robust_fit": "msac"}), None),
    "ours, global, keypoints 0.5": (ours("global", {"keypoint_share": 0.5}), None),
    "ours, global, 2 m / 40": (ours("global", {"grid_step": 2.0, "neighbors": 40}), None),
    "ours, global, 3 m / 30": (ours("global", {"grid_step": 3.0, "neighbors": 30}), None),
    "ours, tracking": (ours("tracking"), None),
    "ours, tracking, 1 mm tolerance": (ours("tracking", registration={"icp_tolerance": 1e-3}), None),
    "Open3D's recipe": (open3d_recipe, "open3d"),
    "small_gicp odometry": (small_gicp_odometry, "small_gicp"),
    "KISS-ICP": (kiss_icp_odometry, "kiss_icp"),
}


KISS_MATCHER_ROWS = {"KISS-Matcher, defaults": False, "KISS-Matcher, yaw only (Quatro)": True}


def kiss_matcher_pairs(scans, truth, matcher_config) -> dict:
    """KISS-Matcher (a ``KISSMatcherConfig``) on each pair of consecutive
    ``scans`` (the later onto the earlier), then the package's ICP from its answer; ``truth`` (N, 4, 4) the
    scans' true poses. Returns per pair ``cpu_ms`` (its ``estimate``),
    ``coarse`` and ``refined`` (translation error at the sensor, m) and
    ``valid`` (its own flag), and ``poses``: the refined motions chained
    from the first true pose. Call it with the process held to one core
    (see :func:`one_core`) for single-core CPU times.
    """
    import kiss_matcher

    matcher = kiss_matcher.KISSMatcher(matcher_config)
    config = Config().with_values(registration=dict(mode="tracking"))  # prepare: the ICP cloud alone
    fit = config.registration
    out = {key: [] for key in ("cpu_ms", "coarse", "refined", "valid")}
    poses, previous = [truth[0]], prepare_frame(scans[0], config)
    for k in range(1, len(scans)):
        current = prepare_frame(scans[k], config)
        start = time.process_time()
        solution = matcher.estimate(scans[k], scans[k - 1])  # source, target: target ~ R source + t
        out["cpu_ms"].append(1000 * (time.process_time() - start))
        coarse = np.eye(4)
        coarse[:3, :3], coarse[:3, 3] = solution.rotation, solution.translation
        refined, _ = refine_icp(
            current.icp,
            previous.icp,
            coarse,
            metric=fit.metric,
            inlier_distance=fit.inlier_distance,
            max_iterations=fit.icp_max_iterations,
            tolerance=fit.icp_tolerance,
            backend=fit.icp_backend,
        )
        true_motion = np.linalg.inv(truth[k - 1]) @ truth[k]
        for key, estimate in (("coarse", coarse), ("refined", refined)):
            out[key].append(float(np.linalg.norm((np.linalg.inv(true_motion) @ estimate)[:3, 3])))
        out["valid"].append(bool(solution.valid))
        poses.append(poses[-1] @ refined)
        previous = current
    return {**{key: np.array(value) for key, value in out.items()}, "poses": np.array(poses)}


class one_core:
    """Hold this process (and the threads it starts meanwhile) to one of its cores, then give the others back."""

    def __enter__(self):
        self.cores = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {min(self.cores)})

    def __exit__(self, *exc):
        os.sched_setaffinity(0, self.cores)


def kiss_matcher_rows(scans, truth, voxel: float) -> None:
    """Print KISS-Matcher's two rows (or that it is missing)."""
    print(f"\nKISS-Matcher on the same {len(scans) - 1} pairs, {voxel} m voxels, one core:", flush=True)
    try:
        import kiss_matcher
    except ImportError:
        for name in KISS_MATCHER_ROWS:
            print(f"{name:<34} not installed: pip install '.[bench]'")
        return
    configs = {
        name: kiss_matcher.KISSMatcherConfig(voxel_size=voxel, use_quatro=q) for name, q in KISS_MATCHER_ROWS.items()
    }
    bounds = next(iter(configs.values()))
    print(f"its noise bounds: matching {bounds.robin_noise_bound:.2f} m, solver {bounds.solver_noise_bound:.2f} m")
    print(
        f"{'system':<34} {'CPU ms/pair med/p90':>19} {'coarse m med/max':>17} {'>1 m':>7} {'invalid':>7}"
        f" {'after ICP m med/max':>19} {'ATE m':>6}"
    )
    for name, matcher_config in configs.items():
        with one_core():
            r = kiss_matcher_pairs(scans, truth, matcher_config)
        off = f"{(r['coarse'] > 1).sum()}/{len(r['coarse'])}"  # pairs off by more than 1 m
        print(
            f"{name:<34} {np.median(r['cpu_ms']):10.1f} / {np.percentile(r['cpu_ms'], 90):6.1f}"
            f" {np.median(r['coarse']):8.2f} / {r['coarse'].max():6.2f} {off:>7}"
            f" {(~r['valid']).sum():7d} {np.median(r['refined']):10.2f} / {r['refined'].max():6.2f}"
            f" {ate(r['poses'], truth).rmse:6.2f}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=None, help="accepted scans to register (default: all)")
    parser.add_argument("--kiss-voxel", type=float, default=VOXEL, help="KISS-Matcher's voxel, m (default 1.5)")
    parser.add_argument(
        "--peers", nargs="+", default=None, metavar="NAME", help="only the rows whose names start so (default: all)"
    )
    parser.add_argument("--no-kiss-matcher", action="store_true", help="leave out the KISS-Matcher rows")
    args = parser.parse_args()
    if (args.scans is not None and args.scans < 2) or not 0 < args.kiss_voxel <= 20:
        parser.exit(2, "error: --scans must be at least 2 and --kiss-voxel between 0 and 20 m\n")
    peers = {n: p for n, p in PEERS.items() if args.peers is None or any(n.startswith(w) for w in args.peers)}
    if not peers:
        parser.exit(2, f"error: no row starts with {' or '.join(args.peers)}: the rows are {'; '.join(PEERS)}\n")
    data = helpers.create_dataset()
    indices = np.arange(0, len(data), Config().registration.skip_frames)[: args.scans]
    scans, truth = [data.scans[i] for i in indices], data.poses[indices]
    print(f"{len(indices)} accepted scans of the default flight ({len(data)} scans)", flush=True)
    rows = []
    for name, (run, module) in peers.items():
        if module is not None:
            try:
                __import__(module)
            except ImportError:
                print(f"{name:<30} missing: pip install '.[bench]'")
                continue
        start, cpu = time.perf_counter(), time.process_time()
        poses = run(scans, truth[0])
        ms = 1000 * (time.perf_counter() - start) / (len(scans) - 1)
        cpu_ms = 1000 * (time.process_time() - cpu) / (len(scans) - 1)
        rows.append((name, ms, cpu_ms, ate(poses, truth).rmse))
        print(f"{name:<30} {ms:8.1f} ms per scan ({cpu_ms:.1f} CPU ms), ATE {rows[-1][3]:.2f} m", flush=True)
    if not rows:
        return
    reference = rows[0]
    print(f"{'system':<30} {'ms/scan':>8} {'x first':>7} {'CPU ms':>7} {'x first':>7} {'ATE m':>7}")
    for name, ms, cpu_ms, error in rows:
        print(f"{name:<30} {ms:8.1f} {ms / reference[1]:7.2f} {cpu_ms:7.1f} {cpu_ms / reference[2]:7.2f} {error:7.2f}")
    if not args.no_kiss_matcher:
        kiss_matcher_rows(scans, truth, args.kiss_voxel)


if __name__ == "__main__":
    main()
