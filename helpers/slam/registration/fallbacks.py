"""The steps of one pair's registration after its matches: the robust fit, ICP from it, and the checks
that may replace that answer by ICP from the flight's last motion (:func:`~.pair.register_frames` runs
them in order). Each check that replaces the answer says why in ``fallback`` and names itself in
``check`` (one of :data:`CHECKS`, which a run counts): a drone does not jump or spin between scans, and
flat or repeating ground matches itself metres away.
"""

from __future__ import annotations

import functools

import numpy as np

from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.slam.motion_guard import BETTER_PAIRED, SAME_MOTION, beyond, clearly_better, offset, with_momentum
from helpers.slam.preprocess import Frame
from helpers.slam.registration.icp import WEAK_CONSTRAINT, pairing
from helpers.slam.registration.overlap import overlap_icp
from helpers.slam.registration.robust_fit import robust_fit

# The checks that may replace a pair's answer, by the names a run counts them under (``Health.counts``,
# ``fallbacks_by_check``); "far off, kept" replaces nothing (ICP from the last motion fitted worse), and is
# counted with the fallbacks all the same.
CHECKS = (
    "robust fit failed",
    "far off, restarted",
    "far off, kept",
    "little paired",
    "flat ground",
    "jump",
    "whole scan",
)


class Refinement:
    """One pair's answer as the steps of :func:`_register` revise it: ``T_coarse`` (the fit, or the guess it was
    replaced by), ``refined`` (ICP's :class:`~.icp.IcpResult`) with ``T_fine`` and ``rmse``, and ``fallback``."""

    def __init__(self, moving: Frame, fixed: Frame, config: Config, guess, icp, stale: int) -> None:
        self.moving, self.fixed, self.config, self.icp, self.stale = moving, fixed, config, icp, stale
        self.fit_settings = config.registration
        self.momentum = guess is not None  # a last motion to fall back on (not the first step's identity)
        self.guess = np.eye(4) if guess is None else guess
        self.crop_at = self.guess if self.momentum else None  # the overlap is cut where the last motion puts it
        self.fallback = self.check = None

    def fit(self, matches: np.ndarray) -> np.ndarray:
        """The robust fit; returns its inliers (none when it failed and ICP starts from the guess)."""
        inliers = np.zeros(len(matches), dtype=bool)
        try:
            moving, fixed = self.moving.points[matches[:, 0]], self.fixed.points[matches[:, 1]]
            self.T_coarse, inliers = robust_fit(moving, fixed, self.fit_settings)
        except SlamError as exc:
            self.T_coarse, self.fallback = (
                self.guess,
                f"robust fit failed ({exc}); ICP started from the previous motion",
            )
            self.check = "robust fit failed"
        return inliers

    def refine(self) -> None:
        self.refined = overlap_icp(self.moving, self.fixed, self.T_coarse, self.fit_settings, self.icp, self.crop_at)
        self.T_fine, self.rmse = self.refined

    def paired_and_constraint(self, T: np.ndarray) -> tuple[float, float]:
        if self.moving.icp is None or self.fixed.icp is None:
            return float("nan"), float("nan")
        return pairing(self.moving.icp, self.fixed.icp, T, self.fit_settings.inlier_distance)

    @functools.cached_property
    def from_guess(self):
        """ICP from the fallback guess and its pairing, computed once however many checks ask for it."""
        retry = overlap_icp(self.moving, self.fixed, self.guess, self.fit_settings, self.icp, crop_at=self.crop_at)
        return retry, self.paired_and_constraint(retry[0])

    def _fit_kept(self) -> bool:
        return not np.allclose(self.T_coarse, self.guess)

    def restart_if_far_off(self) -> None:
        """3. ICP that ends far off (its RMSE) is tried again from the last motion, and the better one kept."""
        fit, rmse = self.fit_settings, self.rmse
        if rmse > fit.icp_fallback_rmse and self.fallback is None:
            retry, _ = self.from_guess
            T_retry, rmse_retry = retry
            self.fallback = f"ICP RMSE {rmse:.2f} m > {fit.icp_fallback_rmse} m from the robust fit; "
            if rmse_retry < rmse:
                self.T_fine, self.rmse, self.T_coarse, self.refined = T_retry, rmse_retry, self.guess, retry
                self.fallback += f"restarted from the previous motion (RMSE {rmse_retry:.2f} m)"
                self.check = "far off, restarted"
            else:
                self.fallback += f"kept (from the previous motion RMSE was {rmse_retry:.2f} m)"
                self.check = "far off, kept"
        self.paired, self.constraint = self.paired_and_constraint(self.T_fine)

    def restart_if_little_paired(self) -> None:
        """4. A fit that pairs little of the scan can still score a low RMSE over its few pairs (flat, sparse
        ground matches itself metres away): ICP from the previous motion too, kept if it pairs clearly more."""
        paired = self.paired
        if paired < self.fit_settings.tracking_min_overlap and self._fit_kept():
            retry, (paired_retry, constraint_retry) = self.from_guess
            if paired_retry > paired + BETTER_PAIRED:  # clearly more: two answers that pair alike are one answer
                self.fallback = (
                    f"ICP from the robust fit paired {paired:.0%} of the points; restarted from the previous "
                    f"motion, which paired {paired_retry:.0%}"
                )
                self.check = "little paired"
                self.refined, self.T_coarse, self.constraint = retry, self.guess, constraint_retry
                self.T_fine, self.rmse = retry

    def doubt_a_jump(self) -> None:
        """5. A result far from the last motion, or turned from it, is doubted: a drone does not jump or spin,
        and flat or repeating ground (a lake, a field, a row of roofs) matches itself metres away or turned
        half round. On ground too flat to pin the motion, ICP from the last motion is kept; with the motion
        guard on, it is the fit's rival anywhere, and the fit must fit clearly better to stay."""
        fit, rmse, paired, constraint = self.fit_settings, self.rmse, self.paired, self.constraint
        self.slide, turn = offset(self.guess, self.T_fine)
        weak = constraint < WEAK_CONSTRAINT
        doubted = beyond((self.slide, turn), fit, turn=1 + self.stale)
        if not (self.momentum and (weak or fit.motion_guard) and doubted and self._fit_kept()):
            return
        retry, (paired_retry, constraint_retry) = self.from_guess
        off = f"{self.slide:.1f} m and {turn:.0f} deg"
        # ICP from the last motion landing where the fit did confirms it (a sharp turn the guess lags behind).
        confirmed = not beyond(offset(retry[0], self.T_fine), fit, SAME_MOTION)
        if not confirmed and (weak or not clearly_better(rmse, paired, retry[1], paired_retry)):
            self.fallback = (
                f"ground too flat to pin the motion (constraint {constraint:.4f}): the fit ended {off} from "
                "the last motion; ICP from the last motion kept"
                if weak
                else f"the fit ended {off} from the last motion and fits no better than ICP from it (RMSE "
                f"{rmse:.2f} against {retry[1]:.2f} m, {paired:.0%} against {paired_retry:.0%} of the points "
                "paired); ICP from the last motion kept"
            )
            self.check = "flat ground" if weak else "jump"
            self.refined, self.constraint = retry, constraint_retry
            self.T_coarse, (self.T_fine, self.rmse) = self.guess, self.refined

    def whole_scan_if_it_stayed(self) -> None:
        """6. A fit that stays metres from the last motion because ICP from it slid the same way may be the
        crop's doing: on flat ground the overlap alone lets both slide along the track. The whole scan from the
        last motion, landing within the jump limits of it, is kept instead (a drone does not jump)."""
        fit, slide = self.fit_settings, self.slide
        if self.momentum and fit.motion_guard and fit.overlap_crop and slide > fit.tracking_max_jump_m:
            if not self._fit_kept():
                return
            uncropped = overlap_icp(self.moving, self.fixed, self.guess, fit, self.icp, whole=True)
            if not beyond(offset(self.guess, uncropped[0]), fit) and uncropped[1] < fit.icp_fallback_rmse:
                self.fallback = (
                    f"the fit ended {slide:.1f} m from the last motion and stayed; ICP on the whole scan from the "
                    f"last motion lands within the jump limits (RMSE {uncropped[1]:.2f} m) and is kept"
                )
                self.check = "whole scan"
                self.refined, self.T_coarse, (self.T_fine, self.rmse) = uncropped, self.guess, uncropped
                self.constraint = self.paired_and_constraint(self.T_fine)[1]

    def follow_momentum(self) -> None:
        """7. What the ground does not pin follows the flight's momentum: on weak ground, ICP's answer and the
        last motion are weighed by how sure each is (ICP's information, and the acceleration a drone may have)."""
        fit = self.fit_settings
        if self.momentum and fit.motion_guard and self.constraint < WEAK_CONSTRAINT:
            self.T_fine = with_momentum(self.guess, self.refined, self.config, 1 + self.stale)
