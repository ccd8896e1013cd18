"""The checks of notebook 1's exercises say ``correct`` for a right answer
and ``not yet`` for a wrong or missing one, on the session's default dataset
(``default_dataset``, tests/conftest.py)."""

import numpy as np

from helpers.exercises import dataset as exercises


def said(capsys) -> str:
    return capsys.readouterr().out.split(":")[0]


def test_the_edge_ray_check_takes_the_hit_and_refuses_others(default_dataset, capsys):
    data = default_dataset
    pose = data.poses[250]
    a = np.radians(data.sensor.azimuth[1])
    hit = exercises._edge_ray(data, 250)
    assert np.isclose((np.linalg.inv(pose) @ np.append(hit, 1))[1], (pose[2, 3] - hit[2]) * np.tan(a), rtol=1e-3)
    assert exercises.check_edge_ray(hit + 0.01, data, 250) and said(capsys) == "correct"
    local = np.linalg.inv(pose) @ np.append(hit, 1.0)
    for wrong in (None, (pose @ (local * [1, -1, 1, 1]))[:3], pose[:3, 3] - [0, 0, 600], hit + [3, 0, 0]):
        assert not exercises.check_edge_ray(wrong, data, 250) and said(capsys) == "not yet"


def test_the_spot_check_counts_the_scans_that_see_it(default_dataset, capsys):
    data = default_dataset
    seen = exercises._scans_seeing(data, 250)
    spot = data.poses[250][:2, 3]
    # known answer: consecutive scans around waypoint 250, each with a return near the spot, and none beyond
    assert seen == list(range(seen[0], seen[-1] + 1)) and seen[0] < 250 < seen[-1]
    for i in (seen[0] - 1, seen[-1] + 1):
        assert np.linalg.norm(data.scan_in_map(i)[:, :2] - spot, axis=1).min() >= exercises.SPOT_RADIUS_M
    assert 20 < len(seen) < 32  # about a 52 m footprint over waypoints 2 m apart
    assert exercises.check_scans_seeing(len(seen), data) and said(capsys) == "correct"
    for wrong in (None, len(seen) - 1, len(seen) + 3):
        assert not exercises.check_scans_seeing(wrong, data) and said(capsys) == "not yet"
