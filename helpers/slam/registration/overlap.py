"""ICP on the part of the moving scan that the fixed scan also saw (stage 3c).

Two consecutive scans overlap only in part: the moving scan's leading edge
covers ground the fixed scan never saw. ICP still pairs those points with
the fixed scan's nearest edge points whenever they lie within its inlier
distance, and each such pair pulls the moving scan back towards the fixed
one: the estimated step comes out short, every step the same way, so a
whole loop shrinks and no loop closure can undo it (issue 21;
``benchmarks/bench_bias.py`` measures it). Leaving those points out before
ICP removes the pull.

The fixed scan's *footprint* is its outline seen from above in its own
frame (the sensor frame's z is up and the rays look down): the convex hull
of its points' x and y. A moving point is kept when the registration's
start ``T_fixed_moving`` places it inside that outline shrunk by a margin
(the inlier distance: nearer to the edge, a point may pair with an edge
point it does not belong to). The outline is the fixed scan's whatever the
scans' headings, so a turn, a hover or a yaw of 90 degrees between the two
crops along whichever edges they share, not along one direction of flight.

The odometry crops where the last motion (a constant-velocity guess, a few
decimetres off on a steady flight; the crop's margin is the inlier distance)
puts the scan, and registers once (:mod:`helpers.slam.registration.pair`): from the robust
fit in the global workflow, from the guess when tracking. Where there is no
last motion (a first step, a pair registered alone) it registers the whole
scan first and crops where that put it, then refines once more. Cropping
after a first registration of the whole scan had left the steps of low
flights short: the leading edge pulled that first answer back, and over flat
ground the second registration stayed near it. The edges back register whole
scans: cropped, they left the default flight's map worse and their step
lengths no truer (the ray rows pull those longer steps more than the leading
edge does; ``benchmarks/bench_bias.py``).

A loop edge pairs a scan with one from an earlier pass, often half over
ground that pass never saw (the first scans of a second lap come back over
the start from outside it). Registered whole, such a scan slid 1-3.8 m
towards pairing more of itself: a false loop. :func:`on_overlap` registers
the loop's best match again on the part of the scan over the old scan's
footprint, with no margin (the pose is an ICP answer by then, not a guess),
crops again where that puts the scan, and so on until the part kept stops
changing: each round leaves out more of the ground the old scan never saw.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from helpers.config.tables import RegistrationConfig
from helpers.geometry import transform_points
from helpers.slam.registration.icp import IcpCloud, icp_cloud
from helpers.slam.registration.icp_service import IcpService

if TYPE_CHECKING:
    from helpers.slam.preprocess import Frame

MIN_KEPT = 30  # points: a crop that keeps fewer leaves ICP too little to fit six degrees of freedom; keep all then


def footprint(points: np.ndarray) -> np.ndarray | None:
    """The outline of ``points`` (N, 3) seen from above: (F, 3) half-planes ``a x + b y + c <= 0``
    with ``(a, b)`` a unit outward normal, so ``a x + b y + c`` is the signed distance to that edge.
    None when the points have no area from above (fewer than three, or all on one line)."""
    xy = np.asarray(points, dtype=np.float64)[:, :2]
    if len(xy) < 3:
        return None
    try:
        return ConvexHull(xy).equations
    except QhullError:  # on one line or one point
        return None


def inside(outline: np.ndarray | None, points: np.ndarray, margin: float) -> np.ndarray:
    """(N,) bool: which ``points`` lie inside ``outline`` (:func:`footprint`) shrunk by ``margin`` metres,
    seen from above (all of them when there is no outline)."""
    points = np.asarray(points, dtype=np.float64)
    if outline is None:
        return np.ones(len(points), dtype=bool)
    distance = points[:, :2] @ outline[:, :2].T + outline[:, 2]  # (N, F) signed distance to each edge
    return (distance <= -margin).all(axis=1)


def overlap(moving: np.ndarray, fixed: np.ndarray, T_fixed_moving: np.ndarray, margin: float) -> np.ndarray:
    """(N,) bool: the ``moving`` points (N, 3) that ``T_fixed_moving`` places inside the footprint of
    ``fixed`` (M, 3), shrunk by ``margin`` metres."""
    moved = transform_points(np.asarray(moving, dtype=np.float64), np.asarray(T_fixed_moving, dtype=np.float64))
    return inside(footprint(fixed), moved, margin)


def crop(moving: np.ndarray, fixed: np.ndarray, T_fixed_moving: np.ndarray, margin: float) -> np.ndarray:
    """The ``moving`` points inside the fixed cloud's footprint at ``T_fixed_moving``; ``moving`` itself
    (the same array) when the crop would leave out none of them or keep fewer than :data:`MIN_KEPT`."""
    keep = overlap(moving, fixed, T_fixed_moving, margin)
    if keep.all() or keep.sum() < MIN_KEPT:
        return moving
    return moving[keep]


def cropped_cloud(moving: IcpCloud, fixed: np.ndarray, T_fixed_moving: np.ndarray, margin: float) -> IcpCloud:
    """``moving`` (made ready for ICP) cropped to the fixed cloud's footprint and made ready again for the
    same metric and back end (its normals then come from the kept points); ``moving`` itself when the crop
    keeps every point (or too few, see :func:`crop`)."""
    points = crop(moving.points, fixed, T_fixed_moving, margin)
    if points is moving.points:
        return moving
    return icp_cloud(points, moving.metric, moving.backend)


def overlap_icp(
    moving: Frame,
    fixed: Frame,
    T_fixed_moving: np.ndarray,
    fit: RegistrationConfig,
    icp=None,
    crop_at=None,
    whole=False,
):
    """ICP between the prepared clouds of two :class:`helpers.slam.preprocess.Frame` (bare points for a frame built by
    hand): ``(T_fixed_moving, rmse)``, an :class:`helpers.slam.registration.icp.IcpResult` with its information.

    With ``[registration] overlap_crop`` the moving cloud is cropped to the fixed scan's footprint where a
    first ICP on the whole scan put it, and registered again; given ``crop_at`` (4 x 4: the last motion,
    within a few decimetres on a steady flight), it is cropped there and registered once: the crop's
    margin is the inlier distance, metres. ``whole``: the whole scan, registered once."""
    wanted = (fit.metric, fit.icp_backend)
    source = moving.icp if moving.icp and (moving.icp.metric, moving.icp.backend) == wanted else moving.icp_points
    target = fixed.icp if fixed.icp and (fixed.icp.metric, fixed.icp.backend) == wanted else fixed.icp_points
    icp = icp or IcpService.from_config(fit)
    cap = fit.icp_max_iterations

    def cropped_at(T):  # the moving points the fixed scan also saw, at T
        if isinstance(source, IcpCloud):
            return cropped_cloud(source, fixed.icp_points, T, fit.inlier_distance)
        return crop(source, fixed.icp_points, T, fit.inlier_distance)

    if fit.overlap_crop and crop_at is not None:
        return icp.align(moving=cropped_at(crop_at), fixed=target, T_fixed_moving=T_fixed_moving, max_iterations=cap)
    refined = icp.align(moving=source, fixed=target, T_fixed_moving=T_fixed_moving, max_iterations=cap)
    if fit.overlap_crop and not whole:  # again on the overlap where ICP put the scan
        T = refined[0]
        cropped = cropped_at(T)
        if cropped is not source:  # the result, information included, of the registration on the overlap
            refined = icp.align(moving=cropped, fixed=target, T_fixed_moving=T, max_iterations=cap)
    return refined


def on_overlap(
    moving: np.ndarray, fixed: np.ndarray, T_fixed_moving: np.ndarray, icp: IcpService, rounds: int, cap=None
):
    """``moving`` (N, 3) registered onto ``fixed`` (M, 3) on its part over ``fixed``'s footprint (no margin)
    where ``T_fixed_moving`` puts it, then cropped again where that registration puts it, and so on: an
    :class:`.icp.IcpResult` (calibrated information), or None when the footprint holds every point
    (or fewer than :data:`MIN_KEPT`) at ``T_fixed_moving``, which then stands.

    It stops when the part kept is one it kept before (a fixed point, or two near-equal answers in turn as
    a few boundary points go in and out) or after ``rounds`` registrations. ``cap``: ICP iterations a round."""
    outline = footprint(fixed)
    target = icp.target(fixed)
    T, fit, seen = np.asarray(T_fixed_moving, dtype=np.float64), None, set()
    for _ in range(rounds):
        keep = inside(outline, transform_points(moving, T), 0.0)
        key = np.packbits(keep).tobytes()
        if key in seen or keep.sum() < MIN_KEPT or (fit is None and keep.all()):
            break
        seen.add(key)
        fit = icp.align(moving=moving[keep], fixed=target, T_fixed_moving=T, max_iterations=cap)
        T = fit.T_fixed_moving
    return fit
