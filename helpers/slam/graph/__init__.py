"""Stage 6, the pose graph: factors, edge information, the GTSAM optimiser (see :mod:`helpers.slam`)."""
