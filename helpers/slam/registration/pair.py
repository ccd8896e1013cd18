"""One pair of prepared scans registered (stage 3c).

Each scan comes prepared once (:mod:`helpers.slam.preprocess`: its clouds, its
descriptors, its ICP cloud). :func:`register_frames` matches descriptors, fits a transform robustly
(MSAC, rigid or yaw and translation: ``[registration] robust_fit``) and
refines it by ICP, the flight's last motion guarding each step
(:mod:`helpers.slam.motion_guard`); :func:`track_frames` runs ICP alone from the
last motion. The ICP stops once an iteration moves no point by more than
``[registration] icp_tolerance`` metres (small_gicp, the default back end;
with Open3D's, once it changes the RMSE by less than that and the inlier
fraction by less than that fraction: :func:`helpers.slam.registration.icp.refine_icp`);
``benchmarks/bench_registration.py`` measures what this tolerance costs and
changes.

A registration returns ``T_fine``, the transform ``T_fixed_moving`` that
carries the moving scan into the fixed scan's frame.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.geometry import check_points, transform_points
from helpers.slam.motion_guard import beyond, offset
from helpers.slam.preprocess import Frame, describe, elapsed_ms, prepare
from helpers.slam.registration.fallbacks import Refinement
from helpers.slam.registration.icp import WEAK_CONSTRAINT, pairing
from helpers.slam.registration.icp_service import IcpService
from helpers.slam.registration.matching import match_features
from helpers.slam.registration.overlap import overlap_icp

STAGES = ("downsample", "fpfh", "match", "msac", "icp")


@dataclass
class PairRegistration:
    """Everything one scan-to-scan registration produced (moving -> fixed)."""

    moving: np.ndarray  # (N, 3) downsampled moving scan
    fixed: np.ndarray  # (M, 3) downsampled fixed scan
    matches: np.ndarray  # (K, 2) index pairs (moving, fixed)
    inliers: np.ndarray  # (K,) bool, matches the robust fit kept
    T_coarse: np.ndarray  # 4 x 4, robust fit (or the fallback guess)
    T_fine: np.ndarray  # 4 x 4, after ICP
    rmse: float  # m, ICP inlier RMSE
    timings: dict  # ms per stage
    fallback: str | None = None  # why the robust fit or ICP was replaced, if it was
    check: str | None = None  # the check that replaced it (one of helpers.slam.registration.fallbacks.CHECKS)
    tracked: bool = False  # True: ICP from the last motion alone, no features (tracking mode)
    constraint: float = float("nan")  # how well ICP's pairs pin the translation (helpers.slam.registration.icp.pairing)
    information: np.ndarray | None = None  # 6 x 6 of T_fine, translation first, as the ICP service calibrates it
    ungated: bool = False  # the gated match (:func:`gate`) ended in a fallback: matched again without the gate

    def blind(self, motion: np.ndarray) -> bool:
        """Whether this step measured nothing: ICP started from ``motion`` (the last motion) on ground too flat
        to move it (no fit, or the fit doubted)."""
        return bool(self.constraint < WEAK_CONSTRAINT and np.allclose(self.T_coarse, motion))


def track_frames(moving: Frame, fixed: Frame, config: Config, motion: np.ndarray, icp: IcpService | None = None):
    """Register ``moving`` onto ``fixed`` by ICP alone, from the last ``motion``
    (a constant-velocity guess). Returns the registration and, when it cannot
    be trusted, why: an ICP RMSE above ``icp_fallback_rmse``, a result that
    jumps more than ``tracking_max_jump_m`` / ``tracking_max_jump_deg`` from the
    guess, or fewer than ``tracking_min_overlap`` of the points paired."""
    fit = config.registration
    start = time.perf_counter()
    refined = overlap_icp(moving, fixed, motion, fit, icp, crop_at=motion)
    T_fine, rmse = refined
    jump_m, jump_deg = offset(motion, T_fine)
    paired, constraint = pairing(moving.icp, fixed.icp, T_fine, fit.inlier_distance)
    timings = {"icp": elapsed_ms(start)}
    reasons = []
    if not rmse <= fit.icp_fallback_rmse:
        reasons.append(f"ICP RMSE {rmse:.2f} m > {fit.icp_fallback_rmse} m")
    if beyond((jump_m, jump_deg), fit):
        reasons.append(f"{jump_m:.2f} m and {jump_deg:.2f} deg from the last motion")
    if paired < fit.tracking_min_overlap:
        reasons.append(f"{paired:.0%} of the points paired")
    none = np.zeros((0, 2), dtype=np.int64)
    pair = PairRegistration(
        moving.points,
        fixed.points,
        none,
        np.zeros(0, bool),
        motion,
        T_fine,
        rmse,
        timings,
        tracked=True,
        constraint=constraint,
        information=refined.information,
    )
    return pair, "; ".join(reasons)


def gate(moving: Frame, fixed: Frame, config: Config, guess: np.ndarray | None):
    """The matcher's gate in space for one step (``near`` of :func:`helpers.slam.registration.matching.match_features`),
    or None: no last motion ``guess``, or ``[features] match_gate = 0``.

    A drone does not jump or spin between scans, so a moving point lands near
    where the last motion puts it: a motion at the jump limits from it
    (``tracking_max_jump_m``, ``tracking_max_jump_deg``) shifts the scan's
    farthest point (horizontally ``r`` from the sensor) by at most
    ``jump_m + 2 sin(jump_deg / 2) r``. The gate's cells are ``match_gate``
    times that wide, and a descriptor is compared only with the other scan's
    in its own cell and the 8 around it (about a tenth of them on the
    default flight).
    """
    factor, fit = config.features.match_gate, config.registration
    if guess is None or factor <= 0:
        return None
    far = float(np.max(np.hypot(moving.points[:, 0], moving.points[:, 1])))
    cell = factor * (fit.tracking_max_jump_m + 2 * np.sin(np.radians(fit.tracking_max_jump_deg) / 2) * far)
    if not cell > 0:  # jump limits of zero: no motion is allowed a shift, so there is nothing to gate by
        return None
    on_moving, on_fixed = moving.described(), fixed.described()
    moved = transform_points(moving.points[on_moving], guess)
    return moved[:, :2], fixed.points[on_fixed, :2], cell


def register_frames(
    moving: Frame, fixed: Frame, config: Config, guess: np.ndarray | None = None, icp=None, stale: int = 0
):
    """Register ``moving`` onto ``fixed``; ``guess`` (4 x 4) is the fallback
    initial transform (identity if None) when the robust fit fails or ICP
    ends far off. Never raises on a hard pair: the reason is in ``fallback``.
    ``icp`` is the run's :class:`helpers.slam.registration.icp_service.IcpService` (one from
    ``[registration]`` when None). ``stale``: the steps since the scans last
    measured the motion (it crossed a lake): the drone may have begun a turn
    meanwhile, so the motion guard's turn limit and the guess's rotation sigmas
    are ``1 + stale`` times wider.

    With a fresh last motion (``guess`` given, ``stale`` 0) the descriptors
    are matched within the :func:`gate`; a gated step that ends in a fallback
    (the fit failed, doubted or replaced) is registered again without the
    gate, and that registration is returned (``ungated``), its timings
    including both."""
    near = gate(moving, fixed, config, guess) if stale == 0 else None
    pair = _register(moving, fixed, config, guess, icp, stale, near)
    if near is not None and pair.fallback is not None:
        again = _register(moving, fixed, config, guess, icp, stale, None)
        again.timings, again.ungated = _add(pair.timings, again.timings), True
        return again
    return pair


def _register(moving: Frame, fixed: Frame, config: Config, guess, icp, stale: int, near):
    """:func:`register_frames` with the matcher's gate ``near`` (None: none): match, fit, refine, then the
    checks that may replace the answer by ICP from the last motion (each names itself in ``fallback``)."""
    timings = {}
    # 1. Match the keypoints' descriptors (current scan = moving, previous scan = fixed).
    start = time.perf_counter()
    matches = _matches(moving, fixed, config.features, near)
    timings["match"] = elapsed_ms(start)
    # 2. Robust fit on the matched points (rigid, or yaw and translation: [registration] robust_fit).
    start = time.perf_counter()
    pair = Refinement(moving, fixed, config, guess, icp, stale)
    inliers = pair.fit(matches)
    timings["msac"] = elapsed_ms(start)
    # 3.-7. Refine with ICP, then check the answer against the last motion.
    start = time.perf_counter()
    pair.refine()
    pair.restart_if_far_off()
    pair.restart_if_little_paired()
    pair.doubt_a_jump()
    pair.whole_scan_if_it_stayed()
    pair.follow_momentum()
    timings["icp"] = elapsed_ms(start)
    return PairRegistration(
        moving.points,
        fixed.points,
        matches,
        inliers,
        pair.T_coarse,
        pair.T_fine,
        pair.rmse,
        timings,
        pair.fallback,
        check=pair.check,
        constraint=pair.constraint,
        information=pair.refined.information,
    )


def _matches(moving: Frame, fixed: Frame, features, near) -> np.ndarray:
    """(K, 2) matched keypoints as indices of the frames' points (moving, fixed)."""
    on_moving, on_fixed = moving.described(), fixed.described()
    for frame, chosen, which in ((moving, on_moving, "moving"), (fixed, on_fixed, "fixed")):
        if len(frame.features) != len(chosen):
            raise SlamError(f"the {which} frame has {len(frame.features)} descriptors for {len(chosen)} keypoints")
    if not (len(on_moving) and len(on_fixed)):  # a scan too sparse to describe: nothing to match, the fit fails
        return np.zeros((0, 2), dtype=np.int64)
    matches = match_features(moving.features, fixed.features, features.match_threshold, features.match_ratio, near)
    return np.column_stack([on_moving[matches[:, 0]], on_fixed[matches[:, 1]]])


def register_pair(moving_scan, fixed_scan, config: Config | None = None, guess=None) -> PairRegistration:
    """Downsample, describe, match, fit and refine one pair of scans
    (moving -> fixed), returning everything a figure needs."""
    config = config or Config()
    moving = describe(prepare(check_points(moving_scan, "the moving scan"), config), config)
    fixed = describe(prepare(check_points(fixed_scan, "the fixed scan"), config), config)
    result = register_frames(moving, fixed, config, guess)
    result.timings = _add(moving.timings, result.timings)
    return result


def _add(*timings: dict) -> dict:
    """Stage timings (ms) summed stage by stage."""
    out = {}
    for part in timings:
        for stage, ms in part.items():
            out[stage] = out.get(stage, 0.0) + ms
    return out
