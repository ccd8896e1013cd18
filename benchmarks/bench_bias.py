"""Step-length bias per registration stage: how long the estimated step is against the true one.

    nice -n 10 .venv/bin/python benchmarks/bench_bias.py [--flights default-700 autzen-150 ...]
        [--experiment stages|before|grid|icpgrid|surface|start|skip|metric|crop|epsilon|steep|rows|rowless]
        [--pairs N]

Each flight is a stretch of a loop; its parameters are fitted to it as ``run``
fits them (:func:`helpers.slam.flight_fit.fit_to_flight`). Consecutive accepted scans
are registered by the odometry's own code (:func:`helpers.slam.odometry.register_frames`,
with the overlap crop of :mod:`helpers.slam.registration.overlap` when the configuration has it,
as it has by default) and, for every pair, the estimated translation is
compared with the true one in the fixed scan's true sensor frame (x along the
track, y across, z up). The ratio ``along`` is the estimate's component along
the true step over the true step length; ``norm`` is the estimate's length
over the true length. Stages: ``coarse`` (FPFH, matching and MSAC), ``icp``
(the refinement from the coarse fit) and ``chain`` (ten consecutive ICP steps
chained, against the true motion over those ten steps: rotation errors
shorten or lengthen it too). ``sparse-150`` is the default scene resampled
as a tile of Autzen's density and flown 150 m above its ground.

The experiments test one hypothesis each on the same pairs (the brief of issue 21):
``before`` the code before the overlap crop against the code as shipped;
``crop`` ICP on the whole moving scan against the shipped crop;
``grid`` the grid average in each scan's own frame against a world-aligned grid,
a finer grid and no grid for ICP; ``icpgrid`` the ICP grid twice and half the
fitted one; ``surface`` the tile's 1 m height field (holes filled from the
nearest cell) against holes filled linearly or smoothed, and the default
scene's own mesh against the same scene resampled as a sparse tile; ``start``
ICP from the coarse fit against ICP from the true pose and from no motion;
``skip`` the step length (overlap of consecutive scans, and the step against
the spacing of the ray rows); ``metric`` the ICP metric; ``epsilon`` thinner
generalized-ICP planes (less weight on residuals along the surface);
``steep`` ICP without the points on steep surfaces; ``rows`` the same flight
with another along-track ray spacing (the sensor's elevation step: does ICP
lock onto the ray rows?); ``rowless`` every fixed scan's ICP cloud resampled
from the surface through its points, without ray rows to lock onto.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

os.environ.setdefault("OMP_WAIT_POLICY", "passive")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
import open3d as o3d
from scipy.interpolate import LinearNDInterpolator, RegularGridInterpolator, griddata
from scipy.ndimage import gaussian_filter
from scipy.spatial import Delaunay

from helpers import SensorConfig, default_scene, read_waypoints
from helpers.config.tables import Config
from helpers.sim.dataset import DEFAULT_WAYPOINTS, MAP_CELL, Dataset, LazyScans, fitted_loop
from helpers.sim.maps import IDENTITY_FRAME, height_field_from_points, read_map
from helpers.sim.scene import HeightField
from helpers.sim.sensor import Surface, poses_from_waypoints
from helpers.slam.flight_fit import fit_to_flight, flight_of
from helpers.slam.odometry import Frame, describe, register_frames
from helpers.slam.registration.features import grid_average
from helpers.slam.registration.icp import GICP_EPSILON, gicp_covariances, icp_cloud
from helpers.slam.registration.pair import track_frames

AUTZEN = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "autzen_trim.laz")
CHAIN = 10  # steps chained for the ``chain`` stage
FAILED = 1.0  # m: a pair whose translation is off by more failed (its own column; left out on the right)
SMOOTHING = 2.0  # cells: the Gaussian that takes the steep slopes out of a tile's surface (the surface experiment)
SPARSE_DENSITY = 1.8  # points per m² when the default scene is resampled as a tile (Autzen's density)

# name: (scene, metres above the ground, first waypoint of the stretch, surface variant: see surface_of)
FLIGHTS = {
    "default-700": ("default", None, 0, "tile"),
    "default-150": ("default", 150.0, 0, "tile"),
    "sparse-150": ("default", 150.0, 0, "sparse"),
    "seed11-700": ("seed11", None, 0, "tile"),
    "autzen-150": ("autzen", 150.0, 0, "tile"),
    "autzen-250": ("autzen", 250.0, 0, "tile"),
}
SHARED = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data")
for _tile in ("forest_bc_1", "forest_bc_2", "farmland_fr", "lake_mountain", "steep_afghanistan", "urban_toronto"):
    FLIGHTS[f"{_tile}-150"] = (f"tile:{_tile}", 150.0, 0, "tile")  # the tiles of ../shared/data, their loop
EXPERIMENT_FLIGHTS = ("sparse-150", "autzen-150")
EXPERIMENTS = ("stages", "before", "grid", "icpgrid", "surface", "start", "skip", "metric", "crop", "epsilon", "steep")
EXPERIMENTS += ("rows", "rowless")


def surface_of(scene: str, variant: str = "tile") -> tuple[HeightField, np.ndarray]:
    """A scene's height field and its loop's waypoints (XY). ``variant``: ``tile`` as the package builds
    it; ``linear`` a tile's holes filled by linear interpolation; ``sparse`` the procedural scene resampled
    at the density of a tile and rebuilt as the package rebuilds a tile."""
    if scene.startswith("tile:"):
        from helpers.sim.flight_plan import loop_plan

        name = scene.removeprefix("tile:")
        path = next(os.path.join(SHARED, f) for f in os.listdir(SHARED) if f.startswith(name + "."))
        tile = read_map(path)
        field = height_field_from_points(tile.points, tile.labels, MAP_CELL)
        return field, loop_plan(field, 150.0)[:, :2]
    if scene == "autzen":
        tile = read_map(AUTZEN)
        field = height_field_from_points(tile.points, tile.labels, MAP_CELL)
        if variant == "linear":
            field = _filled_linearly(field, tile.points)
        if variant == "smooth":
            z = gaussian_filter(field.z, SMOOTHING)
            field = HeightField(field.x0, field.y0, field.cell, z, field.labels, field.valid)
        return field, fitted_loop(field)
    field = default_scene() if scene == "default" else default_scene(seed=int(scene.removeprefix("seed")))
    if variant == "sparse":
        rng = np.random.default_rng(0)
        xmin, xmax, ymin, ymax = field.bounds
        n = int(SPARSE_DENSITY * (xmax - xmin) * (ymax - ymin))
        xy = rng.uniform([xmin, ymin], [xmax, ymax], (n, 2))
        x, y = field.grid()
        z = RegularGridInterpolator((y[:, 0], x[0]), field.z)(xy[:, ::-1])
        labels = field.labels[field.cell_of(xy)]
        field = height_field_from_points(np.column_stack([xy, z]), labels, MAP_CELL)
    return field, read_waypoints(DEFAULT_WAYPOINTS)[:, :2]


def _filled_linearly(field: HeightField, points: np.ndarray) -> HeightField:
    """``field`` with the cells no point fell in interpolated linearly from the cells that hold points."""
    x, y = field.grid()
    ij = np.floor((points[:, :2] - [field.x0 - field.cell / 2, field.y0 - field.cell / 2]) / field.cell).astype(int)
    hit = np.zeros(field.shape, bool)
    hit[ij[:, 1], ij[:, 0]] = True
    z = field.z.copy()
    z[~hit] = griddata((x[hit], y[hit]), field.z[hit], (x[~hit], y[~hit]), method="linear")
    z = np.where(np.isnan(z), field.z, z)
    return HeightField(field.x0, field.y0, field.cell, z, field.labels, field.valid)


def flight(name: str, pairs: int, skip: int | None = None, variant: str | None = None, elevation_step=None):
    """(dataset, fitted config) of a flight: a stretch giving ``pairs`` pairs of accepted scans;
    ``variant``: its surface, when not the flight's own (:func:`surface_of`); ``elevation_step`` (deg):
    the sensor's along-track ray spacing, when not the reference's."""
    scene, above, first, own = FLIGHTS[name]
    field, xy = surface_of(scene, variant or own)
    ground = float(np.median(field.z[field.cell_of(xy)]))
    altitude = 700.0 if above is None else ground + above
    sensor = SensorConfig(altitude=altitude, seed=0)
    if elevation_step is not None:
        sensor = dataclasses.replace(sensor, elevation=(*sensor.elevation[:2], elevation_step))
    waypoints = np.column_stack([xy, np.full(len(xy), altitude)])
    whole = Dataset([], poses_from_waypoints(waypoints), waypoints, field, IDENTITY_FRAME, sensor, name)
    config, _ = fit_to_flight(flight_of(whole), Config(sensor=sensor))
    if skip is not None:
        config = config.with_values(registration={"skip_frames": skip})
    stretch = waypoints[first : first + pairs * config.registration.skip_frames + 1]
    poses = poses_from_waypoints(stretch)
    scans = LazyScans(Surface.from_height_field(field), poses, sensor)
    return Dataset(scans, poses, stretch, field, IDENTITY_FRAME, sensor, name), config


def frame(scan: np.ndarray, pose: np.ndarray, config: Config, grid: str = "own", epsilon=None, steep=None) -> Frame:
    """A scan prepared as :func:`helpers.slam.odometry.prepare` does, with its grid chosen by ``grid``:
    ``own`` (the package: cells of the scan's own frame), ``world`` (cells of the map frame, through the
    true pose), ``fine`` (both grids halved), ``raw`` (ICP on every point). ``epsilon``: Open3D's
    generalized-ICP covariances made this thin across their plane (the package's: ``GICP_EPSILON``).
    ``steep``: ICP leaves out the points whose surface is tilted more than this (degrees)."""
    step, icp_step = config.features.grid_step, config.registration.icp_grid_step
    if grid == "fine":
        step, icp_step = step / 2, icp_step / 2
    if grid == "world":
        rotation, origin = pose[:3, :3], pose[:3, 3]
        to_map = scan @ rotation.T + origin
        points, icp_points = ((grid_average(to_map, s) - origin) @ rotation for s in (step, icp_step))
    else:
        points = grid_average(scan, step)
        icp_points = scan if grid == "raw" else grid_average(scan, icp_step)
    fit = config.registration
    ready = icp_cloud(icp_points, fit.metric, fit.icp_backend)
    if steep is not None:
        icp_points = icp_points[np.abs(ready.normals[:, 2]) >= np.cos(np.radians(steep))]
        ready = icp_cloud(icp_points, fit.metric, fit.icp_backend)
    if epsilon is not None:
        ready.cloud.covariances = o3d.utility.Matrix3dVector(gicp_covariances(ready.normals, epsilon))
    return describe(Frame(points, None, icp_points, {}, ready), config)


def resampled(scan: Frame, config: Config) -> Frame:
    """``scan`` as a fixed scan whose ICP cloud has no ray rows: the surface through its ICP points
    (triangulated from above, linear in each triangle) sampled on the ICP grid."""
    points = scan.icp_points
    interpolate = LinearNDInterpolator(Delaunay(points[:, :2]), points[:, 2])
    step, fit = config.registration.icp_grid_step, config.registration
    (x0, y0), (x1, y1) = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    x, y = np.meshgrid(np.arange(x0, x1, step), np.arange(y0, y1, step))
    grid = np.column_stack([x.ravel(), y.ravel(), interpolate(x.ravel(), y.ravel())])
    grid = grid[np.isfinite(grid[:, 2])]
    return dataclasses.replace(scan, icp_points=grid, icp=icp_cloud(grid, fit.metric, fit.icp_backend))


def measure(data: Dataset, config: Config, grid="own", starts=("coarse",), epsilon=None, steep=None, rowless=False):
    """Relative transforms per stage, (pairs, 4, 4) each, and the true ones (``truth``). ``icp`` is the
    odometry's own registration (:func:`helpers.slam.odometry.register_frames`, with the overlap crop when
    ``[registration] overlap_crop`` is on); ``icp<truth`` and ``icp<identity`` the same ICP from those starts.
    ``rowless``: every fixed scan's ICP cloud :func:`resampled` without its ray rows."""
    indices = np.arange(0, len(data.poses), config.registration.skip_frames)
    out = {"truth": [], "coarse": []} | {f"icp<{s}" if s != "coarse" else "icp": [] for s in starts}
    previous = None
    for k, index in enumerate(indices):
        current = frame(data.scans[index], data.poses[index], config, grid, epsilon, steep)
        if previous is not None:
            truth = np.linalg.inv(data.poses[indices[k - 1]]) @ data.poses[index]
            pair = register_frames(current, previous, config)
            out["truth"].append(truth)
            out["coarse"].append(pair.T_coarse)
            out["icp"].append(pair.T_fine)
            for start in starts[1:]:
                init = {"truth": truth, "identity": np.eye(4)}[start]
                out[f"icp<{start}"].append(track_frames(current, previous, config, init)[0].T_fine)
        previous = resampled(current, config) if rowless else current
    return {stage: np.array(transforms) for stage, transforms in out.items()}


def uncropped(config: Config) -> Config:
    """``config`` with ICP on the whole moving scan (no overlap crop)."""
    return config.with_values(registration={"overlap_crop": False})


def chained(relative: np.ndarray, n: int = CHAIN) -> np.ndarray:
    """Products of ``n`` consecutive relative transforms, one per start."""
    out = []
    for start in range(len(relative) - n + 1):
        T = np.eye(4)
        for step in relative[start : start + n]:
            T = T @ step
        out.append(T)
    return np.array(out)


def ratios(estimated: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(along ratio, norm ratio, error (K, 3) along / across / vertical) in the fixed scan's true frame."""
    t_true, t_est = truth[:, :3, 3], estimated[:, :3, 3]
    length = np.linalg.norm(t_true, axis=1)
    along = np.einsum("ij,ij->i", t_est, t_true) / length**2
    return along, np.linalg.norm(t_est, axis=1) / length, t_est - t_true


def report(label: str, result: dict) -> None:
    """One line per stage: ratios over every pair, then over the pairs whose error is below ``FAILED`` m."""
    truth = result["truth"]
    stages = [(s, e, truth) for s, e in result.items() if s != "truth"]
    if len(truth) > CHAIN:
        stages.append(("chain", chained(result["icp"]), chained(truth)))
    for stage, estimated, true in stages:
        along, norm, error = ratios(estimated, true)
        good = np.linalg.norm(error, axis=1) < FAILED * (CHAIN if stage == "chain" else 1)
        g = good if good.any() else np.ones_like(good)
        mean_error = error[g].mean(axis=0)
        print(
            f"{label:<28} {stage:<12} {len(along):4d} {along.mean():7.4f} {np.median(along):7.4f} {along.std():6.4f}"
            f" {norm.mean():7.4f} {(~good).sum():4d} {along[g].mean():7.4f} {np.median(along[g]):7.4f}"
            f" {along[g].std():6.4f} {mean_error[0]:+7.3f} {mean_error[1]:+7.3f} {mean_error[2]:+7.3f}",
            flush=True,
        )


def header(args) -> None:
    print(f"experiment {args.experiment}; ratios estimated / true step; errors (m) in the fixed scan's true frame")
    print(
        f"{'flight / variant':<28} {'stage':<12} {'n':>4} {'along':>7} {'median':>7} {'std':>6} {'norm':>7}"
        f" {'fail':>4} {'along':>7} {'median':>7} {'std':>6} {'e_along':>7} {'e_cross':>7} {'e_vert':>7}"
    )
    print(f"{'':<28} {'':<12} {'':>4} {'all pairs':^29} {'':>4} {'pairs off by < 1 m (chain: 10 m)':^54}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--flights", nargs="+", choices=list(FLIGHTS), help="default: all (stages), or two")
    parser.add_argument(
        "--experiment",
        default="stages",
        choices=EXPERIMENTS,
    )
    parser.add_argument("--pairs", type=int, default=60, help="pairs of accepted scans per flight (default 60)")
    args = parser.parse_args()
    names = args.flights or (list(FLIGHTS) if args.experiment == "stages" else list(EXPERIMENT_FLIGHTS))
    header(args)
    start = time.perf_counter()
    for name in names:
        if args.experiment == "surface":
            variants = ("tile", "linear", "smooth") if FLIGHTS[name][0] == "autzen" else ("tile", "sparse")
            for variant in variants:
                data, config = flight(name, args.pairs, variant=variant)
                report(f"{name} {variant}", measure(data, config))
            continue
        if args.experiment == "rows":
            for step in (0.2, 0.16, 0.1):
                data, config = flight(name, args.pairs, elevation_step=step)
                report(
                    f"{name} rows {step} deg uncropped", measure(data, uncropped(config), starts=("coarse", "truth"))
                )
                report(f"{name} rows {step} deg", measure(data, config))
            continue
        if args.experiment == "skip":
            for skip in (1, 2, 3, 4):
                data, config = flight(name, args.pairs, skip=skip)
                report(f"{name} skip {skip}", measure(data, config))
            continue
        data, config = flight(name, args.pairs)
        fit = config.registration
        if args.experiment == "stages":
            label = f"{name} grids {config.features.grid_step}/{fit.icp_grid_step}"
            report(label, measure(data, config))
        elif args.experiment == "before":
            report(f"{name} before (no crop)", measure(data, uncropped(config)))
            report(f"{name} as shipped", measure(data, config))
        elif args.experiment == "rowless":
            report(f"{name} as shipped", measure(data, config))
            report(f"{name} fixed scans rowless", measure(data, config, rowless=True))
        elif args.experiment == "grid":
            for grid in ("own", "world", "fine", "raw"):
                report(f"{name} grid {grid}", measure(data, config, grid))
        elif args.experiment == "icpgrid":
            for share in (2.0, 1.0, 0.5):
                step = round(fit.icp_grid_step * share, 3)
                report(
                    f"{name} icp grid {step}", measure(data, config.with_values(registration={"icp_grid_step": step}))
                )
        elif args.experiment == "start":
            report(name, measure(data, config, starts=("coarse", "truth", "identity")))
        elif args.experiment == "metric":
            for metric in ("point-to-point", "point-to-plane", "plane-to-plane"):
                report(f"{name} {metric}", measure(data, config.with_values(registration={"metric": metric})))
        elif args.experiment == "crop":
            for grid in ("own", "fine"):
                report(f"{name} {grid} uncropped", measure(data, uncropped(config), grid))
                report(f"{name} {grid} cropped", measure(data, config, grid))
        elif args.experiment == "epsilon":
            config = config.with_values(registration={"icp_backend": "open3d"})
            for epsilon in (GICP_EPSILON, GICP_EPSILON / 10, GICP_EPSILON / 100):
                report(f"{name} open3d eps {epsilon:g}", measure(data, config, epsilon=epsilon))
        elif args.experiment == "steep":
            for steep in (None, 60.0, 45.0, 30.0):
                report(f"{name} steep {steep}", measure(data, config, steep=steep))
    print(f"{time.perf_counter() - start:.0f} s (a busy machine)")


if __name__ == "__main__":
    main()
