"""benchmarks/bench_peers.py's KISS-Matcher peer: its answers are read the right
way round (the later scan onto the earlier), and without it the script says so."""

import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers.config.tables import Config

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_peers.py"


def bench_peers():
    spec = importlib.util.spec_from_file_location("bench_peers", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def consecutive_accepted(dataset, count):
    indices = np.arange(0, len(dataset), Config().registration.skip_frames)[:count]
    return [dataset.scans[i] for i in indices], dataset.poses[indices]


def test_yaw_only_kiss_matcher_lands_near_the_true_motion(default_dataset):
    kiss_matcher = pytest.importorskip("kiss_matcher")
    bench = bench_peers()
    scans, truth = consecutive_accepted(default_dataset, 4)
    cores = os.sched_getaffinity(0)
    with bench.one_core():
        assert len(os.sched_getaffinity(0)) == 1
        result = bench.kiss_matcher_pairs(scans, truth, kiss_matcher.KISSMatcherConfig(voxel_size=1.5, use_quatro=True))
    assert os.sched_getaffinity(0) == cores
    steps = np.linalg.norm(np.diff(truth[:, :3, 3], axis=0), axis=1)
    assert steps.min() > 3  # a motion read backwards or ignored would be off by about twice or once this
    assert result["valid"].all()
    assert result["coarse"].max() < 1.0, result["coarse"]
    assert result["refined"].max() < 0.3, result["refined"]
    assert result["poses"].shape == (4, 4, 4)
    assert np.allclose(result["poses"][0], truth[0])
    assert (result["cpu_ms"] > 0).all()


def test_rows_say_not_installed_without_kiss_matcher(default_dataset, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "kiss_matcher", None)  # import kiss_matcher then raises ImportError
    scans, truth = consecutive_accepted(default_dataset, 3)
    bench_peers().kiss_matcher_rows(scans, truth, 1.5)
    out = capsys.readouterr().out
    assert out.count("not installed") == 2
    assert "KISS-Matcher, yaw only (Quatro)" in out
