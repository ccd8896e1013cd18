"""How far a registration lies from the flight's last motion, and how the
motion guard (``[registration] motion_guard``, :func:`helpers.slam.registration.pair.register_frames`)
weighs a fit against ICP from that motion.

A drone does not jump or spin between two scans: a registration that ends
more than ``tracking_max_jump_m`` from the last motion, or turned more than
``tracking_max_jump_deg`` from it, is doubted (:func:`beyond`); ICP from the
last motion is then its rival, and a tie goes to the flight's momentum
(:func:`clearly_better`). Two registrations within :data:`SAME_MOTION` of those
limits of each other land on one motion, and ICP from the last motion landing
where the fit did confirms the fit. After steps that measured nothing (over
water) the turn limit widens with them (``turn`` in :func:`beyond`).
"""

from __future__ import annotations

import numpy as np

from helpers.config.tables import Config, RegistrationConfig
from helpers.geometry import rotation_angle_deg
from helpers.slam.graph.factors import motion_sigmas
from helpers.slam.graph.information import blended

# A fit that ends far from the last motion beats ICP from the last motion only when it pairs 5 % more of the
# points, or has 80 % of its RMSE or less: a drone does not jump, so a tie goes to the flight's momentum.
BETTER_PAIRED = 0.05
BETTER_RMSE = 0.8
SAME_MOTION = 0.1  # two registrations within a tenth of the jump limits of each other land on one motion


def offset(T: np.ndarray, T_other: np.ndarray) -> tuple[float, float]:
    """How far (m) and how much turned (deg) ``T_other`` lies from ``T`` (4 x 4 each)."""
    gap = np.linalg.inv(T) @ T_other
    return float(np.linalg.norm(gap[:3, 3])), rotation_angle_deg(gap)


def beyond(metres_degrees: tuple[float, float], fit: RegistrationConfig, share: float = 1.0, turn: float = 1.0) -> bool:
    """Whether an :func:`offset` exceeds ``share`` of the jump limits
    (``tracking_max_jump_m`` or ``turn`` times ``tracking_max_jump_deg``)."""
    metres, degrees = metres_degrees
    return metres > share * fit.tracking_max_jump_m or degrees > share * turn * fit.tracking_max_jump_deg


def clearly_better(rmse: float, paired: float, rmse_rival: float, paired_rival: float) -> bool:
    """Whether a registration (``rmse`` m, ``paired`` share) fits clearly better
    than its rival: it pairs :data:`BETTER_PAIRED` more of the points, or has
    :data:`BETTER_RMSE` of the rival's RMSE or less while pairing about as many."""
    return paired > paired_rival + BETTER_PAIRED or (
        rmse <= BETTER_RMSE * rmse_rival and paired >= paired_rival - BETTER_PAIRED / 2
    )


def with_momentum(guess: np.ndarray, refined, config: Config, widen: float = 1.0) -> np.ndarray:
    """ICP's ``refined`` motion blended with the last motion ``guess``
    (:func:`helpers.slam.graph.information.blended`): the guess is as sure as a drone's
    ``[pose_graph] motion_acceleration`` allows over one step (the sigmas of the
    motion factor), its rotation ``widen`` times less sure when the guess is
    old (:func:`helpers.slam.odometry.staleness`: the drone may have begun a turn
    unseen). Without an information (point-to-point ICP), ICP's motion."""
    if refined.information is None:
        return refined[0]
    sigmas = motion_sigmas(max(float(np.linalg.norm(guess[:3, 3])), 1e-3), config.pose_graph)
    sigmas[3:] *= widen  # a turn builds up unseen; the speed changes slowly (translation first, as ICP's)
    return blended(guess, refined[0], refined.information, sigmas)
