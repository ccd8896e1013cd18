"""Every tunable value of the project, in one place, one table per stage.

The defaults are the reference workflow's values; each field's metadata
holds its meaning and, where the reference has it, the reference's
(MATLAB) name. A TOML file overrides any of them, table by table
(:mod:`helpers.config.files` reads and writes it)::

    [sensor]
    altitude = 700.0                 # flight height, m, in the map frame
    [features]
    grid_step = 1.5                  # m
    [loop_closure]
    sub_map_thresh = 15              # submaps

The first table, ``[sensor]``, is the simulator's: it is defined with its
ray-fan checks in :mod:`helpers.config.sensor` and imported here; the SLAM
stages' tables follow in the workflow's order, ``[loop_closure]`` from
:mod:`helpers.config.loop_closure` and the last, ``[pose_graph]``, from
:mod:`helpers.config.pose_graph`. Each stage reads its own table
only. ``Config()`` is the same wherever it is built: the environment changes
no default (:func:`noise_seed_from_environment` is read by the entry points
alone).

Out-of-range values are refused when a table is built, with one sentence
saying which and why (the bounds and their reasons: :mod:`helpers.config.bounds`).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from typing import ClassVar

from helpers.config.bounds import (
    MAX_EDGES_BACK,
    MAX_ITERATIONS,
    MAX_LENGTH,
    MAX_NEIGHBORS,
    MAX_SCANS,
    MAX_TRIALS,
    MIN_GRID,
    MIN_RMSE,
    BoundedTable,
    param,
)
from helpers.config.loop_closure import LoopClosureConfig
from helpers.config.pose_graph import PoseGraphConfig
from helpers.config.sensor import SensorConfig
from helpers.errors import SlamError

NOISE_SEED_VARIABLE = "HELPERS_NOISE_SEED"  # sets the lidar noise seed of the entry points (the robustness run)

METRICS = ("point-to-point", "point-to-plane", "plane-to-plane")
ICP_BACKENDS = ("small_gicp", "open3d")
MODES = ("global", "tracking")
ROBUST_FITS = ("msac", "msac4")  # rigid from samples of 3 matches (the reference); yaw and translation from 2


def noise_seed_from_environment() -> int:
    """``$HELPERS_NOISE_SEED`` when it is set, else 0: the lidar noise seed of a
    run whose caller names none.

    Read by the entry points only: :func:`helpers.create_dataset` without a
    sensor, :func:`helpers.cli.cache.default_run` without a configuration and
    :func:`helpers.config.files.load_config` for a file that sets no ``[sensor]
    seed`` (so the CLI). The variable lets the whole test suite, the
    notebooks' kernels included, run on other lidar noise than the committed
    outputs were made with (docs/DEVELOPMENT.md); ``Config()``
    never reads it.
    """
    value = os.environ.get(NOISE_SEED_VARIABLE, "0")
    if not (value.isascii() and value.isdigit()):  # "²" is a digit to str.isdigit, not to int()
        raise SlamError(f"${NOISE_SEED_VARIABLE} must be a non-negative integer, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class FeaturesConfig(BoundedTable):
    """What each scan is reduced to before registration, and how its features are matched (notebooks 2 and 3)."""

    TABLE: ClassVar[str] = "features"
    grid_step: float = param(1.5, "cell of the grid-average downsampling before features, metres", "gridStep")
    neighbors: int = param(60, "nearest neighbours for normals and FPFH", "neighbors")
    keypoint_share: float = param(
        1.0, "share of each scan's points, the most tilted, that are described and matched (1: all, the reference)"
    )
    match_threshold: float = param(0.1, "largest normalised descriptor distance of a match", "matchThreshold")
    match_ratio: float = param(0.97, "ratio test: best / second-best distance must be below it", "matchRatio")
    match_gate: float = param(
        1.0,
        "with a last motion, a descriptor is compared only with the other scan's near where that motion puts it: "
        "in its grid cell or the 8 around, cells this many times the shift a motion at the jump limits gives the "
        "scan's farthest point (0: with all of them, the reference)",
    )

    def __post_init__(self):
        self._between("grid_step", MIN_GRID, MAX_LENGTH, "a positive number of metres")
        self._within("neighbors", 3, MAX_NEIGHBORS)
        self._between("keypoint_share", 0.01, 1.0, "a share (below 1 %, too few matches for a rigid fit)")
        self._check("match_threshold", lambda v: 0 < v <= 1, "in (0, 1]")
        self._check("match_ratio", lambda v: 0 < v <= 1, "in (0, 1]")
        self._between("match_gate", 0.0, 100.0, "zero (no gate) or a positive factor")


@dataclass(frozen=True)
class RegistrationConfig(BoundedTable):
    """Which scans are registered, the robust fit and ICP (notebook 3)."""

    TABLE: ClassVar[str] = "registration"
    skip_frames: int = param(3, "register every n-th scan only: the accepted scans", "skipFrames")
    max_distance: float = param(1.0, "inlier distance of the robust rigid fit (MSAC), metres", "maxDistance")
    max_num_trials: int = param(3000, "most hypotheses the robust fit draws", "maxNumTrails")
    confidence: float = param(
        0.99, "the robust fit stops once it is this sure to have drawn an all-inlier sample", "Confidence"
    )
    seed: int = param(0, "seed of the robust fit's sampling")
    robust_fit: str = param(
        "msac4",
        "robust fit: msac4 (yaw and translation from samples of 2 matches, its trial cap fitted to "
        "max_num_trials; ICP finds the tilt) or msac (rigid, samples of 3: the reference)",
    )
    metric: str = param("plane-to-plane", "ICP metric: point-to-point, point-to-plane, plane-to-plane", "metric")
    inlier_distance: float = param(3.0, "ICP ignores correspondences farther apart than this, metres", "inlierDistance")
    icp_grid_step: float = param(0.75, "grid of the clouds ICP refines on, metres (0: the feature clouds)")
    icp_backend: str = param("small_gicp", "ICP library: small_gicp (fast) or open3d (the tutorial's first)")
    icp_max_iterations: int = param(30, "most ICP iterations")
    icp_tolerance: float = param(
        1e-2,
        "ICP stops once an iteration moves no point more than this, metres "
        "(Open3D: changes its RMSE and inlier share by less)",
    )
    icp_fallback_rmse: float = param(1.5, "an ICP RMSE above this (metres) counts as a failed registration")
    icp_local_map: int = param(
        1, "scans merged into the cloud ICP registers each scan onto: 1 the previous scan (the reference), n the last n"
    )
    overlap_crop: bool = param(
        True, "ICP leaves out the moving points that land beyond the fixed scan's footprint (false: the reference)"
    )
    motion_guard: bool = param(
        True,
        "the last motion guards each step: the guess is the medoid of the last three steps, a fit that ends "
        "tracking_max_jump_m from it must fit clearly better than ICP from it, and what weak ground does not pin "
        "follows it (false: the reference)",
    )
    mode: str = param(
        "global", "global: features and a robust fit for every scan (the reference); tracking: ICP from the last motion"
    )
    tracking_max_jump_m: float = param(
        1.0,
        "a step that ends this far (m) from the last motion is doubted (tracking: registered globally; global: "
        "ICP from the last motion too)",
    )
    tracking_max_jump_deg: float = param(6.0, "... or turns this much (deg) more or less than it")
    tracking_min_overlap: float = param(
        0.8,
        "a registration pairing a smaller share of its points is doubted "
        "(tracking: registered globally; global: ICP from the last motion too)",
    )

    def __post_init__(self):
        self._check("skip_frames", lambda v: v >= 1, "an integer of at least 1")
        self._within("skip_frames", 1, MAX_SCANS)
        self._between("max_distance", MIN_GRID, MAX_LENGTH, "a positive number of metres")
        self._within("max_num_trials", 1, MAX_TRIALS)
        self._check("confidence", lambda v: 0 < v < 1, "in (0, 1)")
        self._check("seed", lambda v: v >= 0, "zero or a positive integer")
        self._one_of("robust_fit", ROBUST_FITS)
        self._one_of("metric", METRICS)
        self._one_of("icp_backend", ICP_BACKENDS)
        self._between("inlier_distance", MIN_GRID, MAX_LENGTH, "a positive number of metres")
        self._check(
            "icp_grid_step", lambda v: v == 0 or MIN_GRID <= v <= MAX_LENGTH, f"0 or {MIN_GRID} to {MAX_LENGTH:g} m"
        )
        self._within("icp_max_iterations", 1, MAX_ITERATIONS)
        self._between("icp_tolerance", 0.0, 1.0, "zero or a positive number (above 1 ICP stops at once)")
        self._between("icp_fallback_rmse", MIN_RMSE, MAX_LENGTH, "a positive number of metres")
        self._within("icp_local_map", 1, MAX_EDGES_BACK)
        self._check("overlap_crop", lambda v: isinstance(v, bool), "true or false")
        self._check("motion_guard", lambda v: isinstance(v, bool), "true or false")
        self._one_of("mode", MODES)
        self._between("tracking_max_jump_m", 0.0, MAX_LENGTH, "zero or a positive number of metres")
        self._between("tracking_max_jump_deg", 0.0, 180.0, "zero or a positive number of degrees")
        self._check("tracking_min_overlap", lambda v: 0 <= v <= 1, "a share in [0, 1]")


@dataclass(frozen=True)
class MapConfig(BoundedTable):
    """How registered scans are merged into submaps and the map (notebooks 4 and 7)."""

    TABLE: ClassVar[str] = "map"
    align_grid_step: float = param(1.2, "grid of the merge that builds submaps and the map, metres", "alignGridStep")
    n_scans_per_submap: int = param(3, "accepted scans per submap", "nScansPerSubmap")

    def __post_init__(self):
        self._between("align_grid_step", MIN_GRID, MAX_LENGTH, "a positive number of metres")
        self._check("n_scans_per_submap", lambda v: v >= 1, "an integer of at least 1")
        self._within("n_scans_per_submap", 1, MAX_SCANS)


@dataclass(frozen=True)
class Config:
    """The whole configuration: the sensor, then the SLAM stages in the workflow's order."""

    sensor: SensorConfig = field(default_factory=SensorConfig)
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    map: MapConfig = field(default_factory=MapConfig)
    loop_closure: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    pose_graph: PoseGraphConfig = field(default_factory=PoseGraphConfig)

    def __post_init__(self):
        # A table alone may say 0 (find_loop_candidates then searches the submap it is given as current,
        # as its unit tests do); a run may not: the newest submap holds the scan that queries, and the scan
        # would close a loop with itself.
        if self.loop_closure.sub_map_thresh < 1:
            raise SlamError(
                f"[loop_closure] sub_map_thresh must be at least 1 for a run, got {self.loop_closure.sub_map_thresh}: "
                "the newest submap holds the scan that looks for a loop"
            )

    @property
    def icp_grid(self) -> float:
        """The grid step of the clouds ICP registers (odometry, local map, loops, edges back):
        ``[registration] icp_grid_step``, or the feature grid when it is 0."""
        return self.registration.icp_grid_step or self.features.grid_step

    @classmethod
    def reference(cls) -> Config:
        """The reference workflow exactly: the defaults with each of our changes undone."""
        return cls().with_values(**REFERENCE_WORKFLOW)

    def with_values(self, **tables: dict) -> Config:
        """A copy with some values changed: ``config.with_values(features={"grid_step": 1.0})``."""
        return dataclasses.replace(
            self, **{name: dataclasses.replace(getattr(self, name), **values) for name, values in tables.items()}
        )


# Where our defaults depart from the reference workflow, the reference's values (docs/REFERENCE.md says why).
REFERENCE_WORKFLOW = {
    "features": {"match_gate": 0.0},
    "registration": {"robust_fit": "msac", "icp_grid_step": 0.0, "overlap_crop": False, "motion_guard": False},
    "loop_closure": {
        "loop_search_growth": 0.0,
        "min_constraint": 0.0,
        "search": "growth",
        "skip_after_loop": 0,
        "skip_after_closed_place": 0,
        "best_scan_stop": 0.0,
        "overlap_rounds": 0,
        "place_recognition": False,
    },
    "pose_graph": {"edges_back": 1, "graph_weights": "identity", "loop_kernel": "none"},
}
STAGE_TABLES = tuple(f.name for f in dataclasses.fields(Config))  # TOML tables, in workflow order


def describe(table) -> list[tuple[str, object, str, str | None]]:
    """(name, value, meaning, reference name or None) for every parameter of one table."""
    return [
        (f.name, getattr(table, f.name), f.metadata.get("help", ""), f.metadata.get("reference"))
        for f in dataclasses.fields(table)
    ]
