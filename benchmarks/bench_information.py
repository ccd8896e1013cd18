"""Calibration of the edges' information: is each edge's error against the truth as large as its covariance says?

    nice -n 10 .venv/bin/python benchmarks/bench_information.py [--flights default-700 ...] [--pairs N]
        [--save FILE | --load FILE] [--scale S] [--min-sigma-m M] [--min-sigma-deg D] [--information gicp|plane]

Each flight (``bench_bias.flight``: a stretch of a loop, parameters fitted as
``run`` fits them) runs through SLAM with the raw information (scale 1, no
floor). For every edge (odometry steps, edges back, loops) its error against
the truth, ``xi = Log(inv(T_true) @ T_est)`` (translation first, in the moving
scan's frame, the information's convention), is whitened by its information
after calibration (``[pose_graph] information_scale`` and the floor of
``min_sigma_m`` / ``min_sigma_deg``; an edge back's then divided by its span,
as :func:`helpers.slam.graph.build.build_pose_graph` weighs it). Calibrated, ``xi^T I xi`` follows a
chi-square law with 6 degrees of freedom: per degree of freedom its median is
0.89 and its mean 1, and the error along each principal direction of the
covariance, in sigmas, has an RMS of 1. ``weak`` is that RMS along the
direction the edge pins least (translation), ``strong`` along the one it
pins best; ``>3`` the share of directions off by more than 3 sigmas (0.27 %
for a Gaussian).

Without ``--scale`` the scale is the one that makes the pooled median chi-square per
degree of freedom 0.89 over every flight; the table then shows how it holds
flight by flight. The last columns re-optimise each flight's graph with the
fixed ``icp`` sigmas and with the calibrated ``hessian`` information: ATE (m).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
import sys
import time

os.environ.setdefault("OMP_WAIT_POLICY", "passive")
os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import gtsam
import numpy as np
from bench_bias import flight

from helpers.config.pose_graph import INFORMATION_SOURCES
from helpers.quality.metrics import ate
from helpers.slam.graph.build import build_pose_graph
from helpers.slam.graph.factors import pose3
from helpers.slam.graph.information import SWAP_ROTATION_TRANSLATION, calibrated
from helpers.slam.pipeline import run_slam

# label: (bench_bias flight, surface variant)
FLIGHTS = {
    "default-700": ("default-700", "tile"),
    "seed11-700": ("seed11-700", "tile"),
    "sparse-150": ("default-150", "sparse"),
    "autzen-150": ("autzen-150", "tile"),
    "autzen-250": ("autzen-250", "tile"),
}
RAW = {"information_scale": 1.0, "min_sigma_m": 1e-6, "min_sigma_deg": 1e-6}  # the registrations' own information
CHI2_6_MEDIAN = 5.348  # median of a chi-square with 6 degrees of freedom


def error_of(truth: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """``Log(inv(truth) @ estimate)``, translation first (m, rad)."""
    return np.asarray(gtsam.Pose3.Logmap(pose3(np.linalg.inv(truth) @ estimate)))[SWAP_ROTATION_TRANSLATION]


def measure(label: str, pairs: int, information: str = "gicp") -> dict:
    """The edges of one flight: kind, error (6,), raw information (6 x 6); and what re-optimising needs."""
    name, variant = FLIGHTS[label]
    data, config = flight(name, pairs, variant=variant)
    config = config.with_values(pose_graph={**RAW, "information": information})
    result = run_slam(data, config)
    gt = data.poses[result.indices]
    edges = []
    odometry = result.odometry
    for k, (step, info) in enumerate(zip(odometry.relative, odometry.information, strict=True)):
        edges.append(("odometry", k, k + 1, step, info))
    edges += [("back", e.i, e.j, e.relative, e.information) for e in result.extra_edges]
    edges += [("loop", e.i, e.j, e.relative, e.information) for e in result.loops]
    rows = [
        (kind, i, j, error_of(np.linalg.inv(gt[i]) @ gt[j], T), info)
        for kind, i, j, T, info in edges
        if info is not None
    ]
    return {"label": label, "rows": rows, "result": result, "gt": gt, "config": config}


def whiten(rows, scale: float, floor: np.ndarray):
    """Per edge: chi-square per degree of freedom, and the error in sigmas along each principal direction."""
    chi, along = [], []
    for kind, i, j, xi, raw in rows:
        info = calibrated(raw, scale, floor) / (j - i if kind == "back" else 1)  # as build_pose_graph weighs it
        chi.append(xi @ info @ xi / 6)
        values, vectors = np.linalg.eigh(np.linalg.inv(info)[:3, :3])
        full_values, full_vectors = np.linalg.eigh(np.linalg.inv(info))
        weak = vectors[:, -1] @ xi[:3] / np.sqrt(values[-1])
        z = full_vectors.T @ xi / np.sqrt(full_values)
        along.append((weak, z[0], z))
    return np.array(chi), along


def fit_scale(runs, floor: np.ndarray) -> float:
    """The scale whose pooled median chi-square per degree of freedom is that of a chi-square law."""
    scales = np.logspace(-6, 0, 121)
    target = CHI2_6_MEDIAN / 6
    medians = [np.median(np.concatenate([whiten(r["rows"], s, floor)[0] for r in runs])) for s in scales]
    return float(scales[int(np.argmin(np.abs(np.log(np.array(medians) / target))))])


def reoptimised_ate(run, weights: str, scale: float, floor: np.ndarray) -> float:
    """ATE (m) of the flight's graph re-optimised with ``weights``, the information calibrated by (scale, floor)."""
    result, config = run["result"], run["config"]
    cal = lambda info: None if info is None else calibrated(info, scale, floor)  # noqa: E731
    odometry = dataclasses.replace(result.odometry, information=[cal(i) for i in result.odometry.information])
    extra = [dataclasses.replace(e, information=cal(e.information)) for e in result.extra_edges]
    loops = [dataclasses.replace(e, information=cal(e.information)) for e in result.loops]
    config = config.with_values(pose_graph={"graph_weights": weights})
    graph = build_pose_graph(odometry, extra, loops, config)
    optimised = graph.optimize(anchor_pose=run["gt"][0], loop_kernel=config.pose_graph.loop_kernel)
    return ate(optimised.poses, run["gt"]).rmse


def table(runs, scale: float, floor: np.ndarray) -> None:
    print(f"scale {scale:.3g}; floor {floor[0]:g} m, {np.degrees(floor[3]):g} deg")
    print(
        f"{'flight':<12} {'edges':<9} {'n':>4} {'chi2/dof':>8} {'mean':>7} {'weak':>6} {'strong':>6} {'>3':>6}"
        f" {'ATE icp':>8} {'hessian':>8}"
    )
    for run in runs:
        ates = [reoptimised_ate(run, w, scale, floor) for w in ("icp", "hessian")]
        for kind in ("odometry", "back", "loop", "all"):
            rows = [r for r in run["rows"] if kind in ("all", r[0])]
            if not rows:
                continue
            chi, along = whiten(rows, scale, floor)
            weak = np.sqrt(np.mean([a[0] ** 2 for a in along]))
            strong = np.sqrt(np.mean([a[1] ** 2 for a in along]))
            beyond = np.mean(np.abs(np.concatenate([a[2] for a in along])) > 3)
            tail = f" {ates[0]:8.3f} {ates[1]:8.3f}" if kind == "all" else ""
            print(
                f"{run['label']:<12} {kind:<9} {len(rows):4d} {np.median(chi):8.2f} {np.mean(chi):7.2f}"
                f" {weak:6.2f} {strong:6.2f} {beyond:6.1%}{tail}",
                flush=True,
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", nargs="+", choices=list(FLIGHTS), default=list(FLIGHTS))
    parser.add_argument("--pairs", type=int, default=60, help="pairs of accepted scans per flight (default 60)")
    parser.add_argument("--save", help="keep the measured edges in this file (pickle)")
    parser.add_argument("--load", help="read the measured edges from this file instead of flying")
    parser.add_argument("--scale", type=float, help="information_scale (default: fitted)")
    parser.add_argument("--min-sigma-m", type=float, default=0.01)
    parser.add_argument("--min-sigma-deg", type=float, default=0.01)
    parser.add_argument(
        "--information", choices=INFORMATION_SOURCES, default="gicp", help="[pose_graph] information (default gicp)"
    )
    args = parser.parse_args()
    start = time.perf_counter()
    if args.load:
        with open(args.load, "rb") as file:
            runs = [r for r in pickle.load(file) if r["label"] in args.flights]
    else:
        runs = [measure(label, args.pairs, args.information) for label in args.flights]
        if args.save:
            with open(args.save, "wb") as file:
                pickle.dump(runs, file)
    floor = np.array([args.min_sigma_m] * 3 + [np.radians(args.min_sigma_deg)] * 3)
    scale = args.scale if args.scale is not None else fit_scale(runs, floor)
    table(runs, scale, floor)
    print(f"{time.perf_counter() - start:.0f} s (a busy machine)")


if __name__ == "__main__":
    main()
