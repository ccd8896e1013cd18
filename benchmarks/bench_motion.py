"""The motion factor and GNSS fixes on whole flights: ATE with and without each.

    nice -n 10 .venv/bin/python benchmarks/bench_motion.py [--flights default-700 default-150 ...]
        [--scans N] [--swing 0.3] [--gnss-sigma 2] [--set registration.icp_local_map=6 ...]

Each flight (``benchmarks/bench_bias.py``'s scenes and heights, parameters
fitted as ``run`` fits them) is registered once by :class:`helpers.slam.slam.Slam`;
its pose graph is then built and optimised again for every variant: lidar
only, with the constant-velocity factor, with GNSS fixes of the given sigma
(simulated from the true positions, seeded), and with both. ``--swing``
resamples the waypoints so that their spacing, the drone's speed, swings by
this share around the flight's own (a sine over ``SWING_PERIOD`` m of track).
Prints ATE (m, optimised) per variant and the pose graph's time. ``--edges M,DEG``
adds lidar only and GNSS with other fixed edge sigmas (how much the fixes'
effect depends on how sure the edges say they are); ``--set table.key=value``
changes a configuration value after fitting, as ``bench_flights.py``'s does.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

os.environ.setdefault("OMP_WAIT_POLICY", "passive")
os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np
from bench_bias import FLIGHTS, surface_of
from bench_flights import with_settings

from helpers import SensorConfig
from helpers.config.tables import Config
from helpers.quality.metrics import ate
from helpers.sim.dataset import Dataset, LazyScans
from helpers.sim.gnss import GnssFixes, simulate_gnss
from helpers.sim.maps import IDENTITY_FRAME
from helpers.sim.sensor import Surface, poses_from_waypoints
from helpers.slam.flight_fit import fit_to_flight, flight_of
from helpers.slam.graph.build import build_pose_graph
from helpers.slam.graph.factors import gnss_factors
from helpers.slam.slam import Slam

SWING_PERIOD = 400.0  # m of track per period of the speed swing


def swung(xy: np.ndarray, share: float) -> np.ndarray:
    """The polyline ``xy`` resampled with a spacing that swings by ``share`` around its median spacing."""
    along = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    base = float(np.median(np.diff(along)))
    stations = [0.0]
    while True:
        s = stations[-1] + base * (1 + share * np.sin(2 * np.pi * stations[-1] / SWING_PERIOD))
        if s > along[-1]:
            break
        stations.append(s)
    return np.column_stack([np.interp(stations, along, xy[:, 0]), np.interp(stations, along, xy[:, 1])])


def flight(name: str, scans: int | None, swing: float, variant: str | None = None, settings=()):
    scene, above, first, own = FLIGHTS[name]
    field, xy = surface_of(scene, variant or own)
    if swing:
        xy = swung(xy, swing)
    ground = float(np.median(field.z[field.cell_of(xy)]))
    altitude = 700.0 if above is None else ground + above
    sensor = SensorConfig(altitude=altitude, seed=0)
    waypoints = np.column_stack([xy, np.full(len(xy), altitude)])[first : None if scans is None else first + scans]
    poses = poses_from_waypoints(waypoints)
    data = Dataset(LazyScans(Surface.from_height_field(field), poses, sensor), poses, waypoints, field,
                   IDENTITY_FRAME, sensor, name)  # fmt: skip
    config, _ = fit_to_flight(flight_of(data), Config(sensor=sensor))
    return data, with_settings(config, settings)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", nargs="+", default=["default-700"], choices=sorted(FLIGHTS))
    parser.add_argument("--scans", type=int, default=None, help="the first N scans only (default: all)")
    parser.add_argument("--swing", type=float, default=0.0, help="speed swing, a share (0.3: +-30 %%)")
    parser.add_argument("--gnss-sigma", type=float, default=2.0, help="m, horizontal and vertical")
    parser.add_argument("--variant", default=None, help="bench_bias.surface_of's: tile, sparse (the default scene "
                        "resampled at a real tile's density), linear, smooth (default: the flight's own)")  # fmt: skip
    parser.add_argument(
        "--edges", help="M,DEG: also lidar only and GNSS with these [pose_graph] edge sigmas (m and deg per step)"
    )
    parser.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE")
    args = parser.parse_args()
    for name in args.flights:
        data, config = flight(name, args.scans, args.swing, args.variant, args.set)
        start = time.perf_counter()
        slam = Slam(config, anchor=data.poses[0])
        for index in range(len(data)):
            if slam.accepts(index):
                slam.process(data.scans[index], index)
        registered = time.perf_counter() - start
        indices = np.array(slam.indices)
        truth = data.poses[indices]
        odometry = slam.odometry.result()
        fixes = simulate_gnss(data.poses[:, :3, 3], args.gnss_sigma, args.gnss_sigma, seed=0)
        gnss = GnssFixes(np.arange(len(data)), fixes, np.full(3, args.gnss_sigma))
        steps = np.linalg.norm(np.diff(truth[:, :3, 3], axis=0), axis=1)
        print(
            f"{name}{' swing ' + str(args.swing) if args.swing else ''} ({args.variant or FLIGHTS[name][3]}): "
            f"{len(data)} scans, {len(indices)} nodes, "
            f"step {steps.min():.2f}-{steps.max():.2f} m, {len(slam.loops.loops)} loops, "
            f"ATE odometry {ate(odometry.poses, truth).rmse:.3f} m; registered in {registered:.0f} s"
        )
        variants = [
            ("lidar only", False, False, {}),
            ("motion factor", True, False, {}),
            (f"GNSS {args.gnss_sigma:g} m", False, True, {}),
            (f"GNSS {args.gnss_sigma:g} m + motion", True, True, {}),
        ]
        if args.edges:
            metres, degrees = (float(v) for v in args.edges.split(","))
            edges = {"edge_sigma_m": metres, "edge_sigma_deg": degrees}
            variants += [
                (f"lidar, edges {args.edges}", False, False, edges),
                (f"GNSS, edges {args.edges}", False, True, edges),
            ]
        for label, motion, use_gnss, edges in variants:
            table = dataclasses.replace(config.pose_graph, motion_factor=motion, **edges)
            variant = dataclasses.replace(config, pose_graph=table)
            start = time.perf_counter()
            graph = build_pose_graph(odometry, slam.edges_back.sorted(), slam.loops.loops, variant)
            for factor in gnss_factors(gnss, indices) if use_gnss else ():
                graph.add_factor(factor)
            result = graph.optimize(anchor_pose=slam.anchor, loop_kernel=table.loop_kernel)
            error = ate(result.poses, truth)
            print(
                f"  {label:28s} ATE {error.rmse:.3f} m (max {error.max:.3f}); pose graph "
                f"{time.perf_counter() - start:.2f} s, {result.iterations} iterations (busy machine)"
            )


if __name__ == "__main__":
    main()
