"""The coarse fit measured: the package's six-degree-of-freedom MSAC against
the four-degree-of-freedom one (yaw + translation, ``helpers.slam.registration.msac_yaw``) on
the same matches of the same scan pairs, then both refined by the package's ICP.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_coarse_fit.py [--pairs 30] [--flights default,low,autzen]

Flights: ``default`` (the default scene at 700 m, the reference's values),
``low`` (the default scene 150 m above its ground) and ``autzen150`` /
``autzen250`` (the real tile beside the repository, 150 and 250 m above its
ground); the low flights take the values ``helpers.slam.flight_fit`` fits to them, as
``run`` does. Each pair is two consecutive accepted scans (``skip_frames``
apart; ``--apart N``: N accepted scans apart, less overlap, as a loop
candidate or a missed scan gives), the pairs spread evenly over the flight. Descriptors and matches
come from the package's own functions, as the odometry makes them.

Per method: CPU ms of the fit (process time, one thread), samples scored,
the coarse error against the true relative pose (translation at the sensor,
m, and yaw, degrees), the share of pairs off by more than 1 m, the error
along the true motion (negative: the fit slid back towards no motion) and
the error after ICP from that fit. Times are CPU times, so a busy machine
slows them less than wall times, but compare them paired, in one run.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")  # single-thread CPU times
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np
from scipy.spatial.transform import Rotation

import helpers.slam.registration.msac as registration
from helpers import create_dataset
from helpers.config.tables import Config, SensorConfig
from helpers.errors import SlamError
from helpers.slam.flight_fit import fit_to_flight, flight_of
from helpers.slam.odometry import describe, prepare
from helpers.slam.registration.icp import refine_icp
from helpers.slam.registration.matching import match_features
from helpers.slam.registration.msac import trials_needed
from helpers.slam.registration.msac_yaw import fit_yaw, fit_yaw_translation, yaw_transform

AUTZEN = Path(__file__).resolve().parents[2] / "shared" / "data" / "autzen_trim.laz"
LOW_HEIGHTS = {"low": 150.0, "autzen150": 150.0, "autzen250": 250.0}  # m above the ground
RATIOS = (0.05, 0.1, 0.2, 0.3)  # inlier ratios whose standard trial counts are printed
CONFIDENCE = 0.99
ORACLE = "LS on the right matches"  # not a method: the matches' own verdict, for reference


def flight(name: str):
    """The dataset (scans cast when read) and the configuration of one named flight."""
    if name == "default":
        return create_dataset(lazy=True), Config()
    tile = AUTZEN if name.startswith("autzen") else None
    if tile is not None and not tile.is_file():
        raise SystemExit(f"error: the real tile is not at {tile}")
    probe = create_dataset(tile, lazy=True)  # at the default altitude, to find the ground under the loop
    ground = probe.sensor.altitude - flight_of(probe).height
    data = create_dataset(tile, sensor=SensorConfig(altitude=ground + LOW_HEIGHTS[name]), lazy=True)
    config, _ = fit_to_flight(flight_of(data), Config())
    return data, config


def counted_six_dof(moving, fixed, fit):
    """The package's MSAC, with the hypotheses it scored counted."""
    scored = [0]
    original = registration._msac_costs

    def counting(transforms, *args):
        scored[0] += len(transforms)
        return original(transforms, *args)

    registration._msac_costs = counting
    try:
        T, inliers = registration.estimate_rigid_msac(
            moving, fixed, fit.max_distance, fit.max_num_trials, fit.seed, fit.confidence
        )
    finally:
        registration._msac_costs = original
    return T, inliers, scored[0]


def methods(fit, caps):
    """name -> function(moving points, fixed points) giving (T, inliers, samples scored)."""

    def four_dof(cap):
        def run(moving, fixed):
            result = fit_yaw_translation(moving, fixed, fit.max_distance, cap, fit.seed, fit.confidence)
            return result.T, result.inliers, result.trials

        return run

    out = {f"6-DoF MSAC, cap {fit.max_num_trials}": lambda m, f: counted_six_dof(m, f, fit)}
    for cap in (fit.max_num_trials, *caps):
        out[f"4-DoF MSAC, cap {cap}"] = four_dof(cap)
    return out


def errors(estimate: np.ndarray, truth: np.ndarray, points: np.ndarray) -> tuple[float, float, float, float]:
    """Translation error at the sensor (m), yaw error (deg), the translation error along the true motion
    (m) and the RMS distance (m) between ``points`` moved by ``estimate`` and by ``truth`` (on the ground)."""
    error = np.linalg.inv(truth) @ estimate
    yaw = Rotation.from_matrix(error[:3, :3]).as_euler("ZYX", degrees=True)[0]
    offset = estimate[:3, 3] - truth[:3, 3]
    along = offset @ truth[:3, 3] / max(np.linalg.norm(truth[:3, 3]), 1e-9)
    apart = points @ (estimate[:3, :3] - truth[:3, :3]).T + offset
    ground = np.sqrt(np.mean(np.sum(apart**2, axis=1))) if len(points) else np.nan
    return float(np.linalg.norm(error[:3, 3])), abs(float(yaw)), float(along), float(ground)


def measure(name: str, pairs: int, caps, apart: int) -> None:
    data, config = flight(name)
    fit = config.registration
    skip = fit.skip_frames * apart
    starts = np.linspace(0, len(data) - 1 - skip, pairs).round().astype(int)
    print(
        f"\n== {name}: {data.name}, {flight_of(data).height:.0f} m above the ground, {len(starts)} pairs "
        f"{skip} scans apart; grid {config.features.grid_step} m, max_distance {fit.max_distance} m"
    )
    runs = methods(fit, caps)
    rows = {method: [] for method in [*runs, ORACLE]}
    n_matches, ratios = [], []
    for start in starts:
        moving_frame, fixed_frame = (describe(prepare(data.scans[i], config), config) for i in (start + skip, start))
        truth = np.linalg.inv(data.poses[start]) @ data.poses[start + skip]
        matches = match_features(
            moving_frame.features, fixed_frame.features, config.features.match_threshold, config.features.match_ratio
        )
        keep = [f.described() for f in (moving_frame, fixed_frame)]
        moving = moving_frame.points[keep[0][matches[:, 0]]]
        fixed = fixed_frame.points[keep[1][matches[:, 1]]]
        n_matches.append(len(matches))
        right = np.linalg.norm(moving @ truth[:3, :3].T + truth[:3, 3] - fixed, axis=1) < fit.max_distance
        ratios.append(right.mean() if len(right) else 0.0)
        for method in rows:
            cpu = time.process_time()
            try:
                if method == ORACLE:  # what the matches say: a least-squares fit on the right ones only
                    if right.sum() < 2:
                        raise SlamError("fewer than 2 right matches")
                    T, scored = yaw_transform(*fit_yaw(moving[right], fixed[right])), 0
                else:
                    T, _, scored = runs[method](moving, fixed)
            except SlamError:
                rows[method].append((np.nan,) * 7)  # the odometry would fall back to the previous motion
                continue
            ms = 1000 * (time.process_time() - cpu)
            T_icp, _ = refine_icp(
                moving_frame.icp,
                fixed_frame.icp,
                T,
                fit.metric,
                fit.inlier_distance,
                fit.icp_max_iterations,
                fit.icp_tolerance,
                fit.icp_backend,
            )
            rows[method].append((ms, scored, *errors(T, truth, moving), errors(T_icp, truth, moving)[0]))
    ratios = np.array(ratios)
    low = np.percentile(ratios, 10)
    print(
        f"matches per pair: median {np.median(n_matches):.0f} (min {min(n_matches)}); right matches (within "
        f"max_distance of the true motion): median {np.median(ratios):.3f}, 10th percentile {low:.3f}, min "
        f"{ratios.min():.3f}; standard trials at the 10th percentile: 2-point "
        f"{trials_needed(low, CONFIDENCE, 10**9, 2)}, 3-point {trials_needed(low, CONFIDENCE, 10**9, 3)}"
    )
    print(
        "method                  ms med/p90    samples  coarse m med/max  yaw deg med/max  >1 m  along m"
        "  ground m med/max  ICP m med/max  failed"
    )
    reference = np.array(rows[next(iter(rows))])
    for method, values in rows.items():
        v = np.array(values)
        ok = ~np.isnan(v[:, 0])
        w = v[ok]
        print(
            f"{method:<22} {np.median(w[:, 0]):6.1f} / {np.percentile(w[:, 0], 90):5.1f} {np.median(w[:, 1]):8.0f}"
            f"  {np.median(w[:, 2]):6.2f} / {w[:, 2].max():6.2f}  {np.median(w[:, 3]):6.2f} / {w[:, 3].max():6.2f}"
            f"  {(w[:, 2] > 1).sum():2d}/{len(w)}  {np.median(w[:, 4]):+6.2f}  {np.median(w[:, 5]):6.2f} / "
            f"{w[:, 5].max():5.2f}  {np.median(w[:, 6]):5.2f} / {w[:, 6].max():5.2f}  {(~ok).sum():4d}"
        )
        if method not in (next(iter(rows)), ORACLE):
            both = ok & ~np.isnan(reference[:, 0])
            ratio = np.median(v[both, 0] / reference[both, 0])
            print(f"{'':22} CPU time paired with the 6-DoF fit: median ratio {ratio:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=30, help="scan pairs per flight (default 30)")
    parser.add_argument(
        "--apart", type=int, default=1, help="pairs this many accepted scans apart (default 1: consecutive)"
    )
    parser.add_argument("--flights", default="default,low", help="default, low, autzen150, autzen250 (comma-separated)")
    args = parser.parse_args()
    unknown = set(args.flights.split(",")) - {"default", *LOW_HEIGHTS}
    if unknown or args.pairs < 1 or args.apart < 1:
        raise SystemExit(f"error: unknown flights {sorted(unknown)}, or --pairs or --apart below 1")
    print(f"standard RANSAC trials at {CONFIDENCE:.0%} confidence (inlier ratio: 2-point / 3-point samples):")
    for w in RATIOS:
        print(f"  {w:.2f}: {trials_needed(w, CONFIDENCE, 10**9, 2):6d} / {trials_needed(w, CONFIDENCE, 10**9, 3):6d}")
    caps = [trials_needed(w, CONFIDENCE, 10**9, 2) for w in (0.1, 0.2)]
    for name in args.flights.split(","):
        measure(name, args.pairs, caps, args.apart)


if __name__ == "__main__":
    main()
