"""The estimator: the reference's stages, a module each, and :class:`Slam`, which runs them one scan at a time.
It reads its configuration (:mod:`helpers.config`) and nothing of the simulator or the grader.

- :mod:`~helpers.slam.preprocess`: a scan prepared once for every stage (grids, normals, FPFH);
- :mod:`~helpers.slam.registration`: stage 3, scan to scan: :mod:`~.registration.features`
  (``pcdownsample``, ``extractFPFHFeatures``), :mod:`~.registration.matching` (``pcmatchfeatures``),
  :mod:`~.registration.robust_fit` (``estgeotform3d``, both MSAC solvers), :mod:`~.registration.icp`
  (``pcregistericp``), :mod:`~.registration.pair` (one pair, coarse then fine), :mod:`~.registration.overlap`;
- :mod:`~helpers.slam.odometry` (with :mod:`~helpers.slam.motion_guard`): the scans chained into a trajectory;
  :mod:`~helpers.slam.edges_back`: edges to older scans;
- :mod:`~helpers.slam.submaps`: stage 4 (``pcalign``);
- :mod:`~helpers.slam.loops`: stage 5, loop closure (``helperEstimateLoopCandidates``): where to search, which
  submap, which scan, place recognition after a blind stretch;
- :mod:`~helpers.slam.graph`: stage 6, the pose graph in GTSAM (``poseGraph3D``, ``optimizePoseGraph``);
- :mod:`~helpers.slam.flight_fit`: the parameters that scale with the flight's height and spacing;
- :mod:`~helpers.slam.slam`: :class:`Slam`; :mod:`~helpers.slam.pipeline`: a whole dataset through it.
"""

from helpers import lazy_exports

EXPORTS = {
    "Slam": "helpers.slam.slam",
    "SlamResult": "helpers.slam.slam",
    "Step": "helpers.slam.slam",
    "build_pose_graph": "helpers.slam.graph.build",
    "run_slam": "helpers.slam.pipeline",
    "prepare_scan": "helpers.slam.preprocess",
    "fpfh": "helpers.slam.registration.features",
    "grid_average": "helpers.slam.registration.features",
    "normalise_descriptors": "helpers.slam.registration.features",
    "match_features": "helpers.slam.registration.matching",
    "robust_fit": "helpers.slam.registration.robust_fit",
    "equivalent_trials": "helpers.slam.registration.robust_fit",
    "estimate_rigid_msac": "helpers.slam.registration.robust_fit",
    "estimate_yaw_msac": "helpers.slam.registration.robust_fit",
    "ICP_NORMAL_NEIGHBORS": "helpers.slam.registration.icp",
    "icp_rmse": "helpers.slam.registration.icp",
    "refine_icp": "helpers.slam.registration.icp",
    "icp_with": "helpers.slam.registration.icp_service",
    "surface_rmse": "helpers.slam.registration.icp_service",
    "prepare": "helpers.slam.preprocess",
    "register_pair": "helpers.slam.registration.pair",
    "register_frames": "helpers.slam.registration.pair",
    "footprint": "helpers.slam.registration.overlap",
    "inside": "helpers.slam.registration.overlap",
    "on_overlap": "helpers.slam.registration.overlap",
    "run_odometry": "helpers.slam.odometry",
    "local_map": "helpers.slam.odometry",
    "SubmapIndex": "helpers.slam.submaps",
    "build_submap": "helpers.slam.submaps",
    "centre_scan_id": "helpers.slam.submaps",
    "distance_flown_since": "helpers.slam.loops.search",
    "find_loop_candidates": "helpers.slam.loops.search",
    "mahalanobis_gate": "helpers.slam.loops.search",
    "best_scan_registration": "helpers.slam.loops.best_scan",
    "LoopQuery": "helpers.slam.loops.closer",
    "Edge": "helpers.slam.graph.factors",
    "KERNEL_SCALES": "helpers.slam.graph.factors",
    "PRIOR_SIGMAS": "helpers.slam.graph.factors",
    "ConstantVelocityFactor": "helpers.slam.graph.factors",
    "FactorContext": "helpers.slam.graph.factors",
    "constant_velocity_sigmas": "helpers.slam.graph.factors",
    "pose3": "helpers.slam.graph.factors",
    "PoseGraph": "helpers.slam.graph.optimizer",
    "fit_to_flight": "helpers.slam.flight_fit",
    "flight_of": "helpers.slam.flight_fit",
}
__all__ = sorted(EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, EXPORTS)
