"""benchmarks/bench_gate.py's count of the descriptors the gate compares, against a plain count."""

import importlib.util
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_gate.py"


def test_the_compared_share_is_the_share_of_fixed_points_in_touching_cells():
    spec = importlib.util.spec_from_file_location("bench_gate", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rng = np.random.default_rng(2)
    fixed = rng.uniform([-120, -25], [120, 25], (700, 2))
    moving = fixed[:400] + rng.normal(0, 5, (400, 2))
    for cell in (7.0, 16.0, 400.0):
        cm, cf = np.floor(moving / cell), np.floor(fixed / cell)
        plain = (np.abs(cm[:, None] - cf[None]) <= 1).all(axis=2).mean()
        assert abs(module.compared_share(moving, fixed, cell) - plain) < 1e-12
    assert module.compared_share(moving, fixed, 400.0) == 1.0  # one cell holds every point
