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


def test_the_footprint_check_takes_the_width_and_refuses_others(default_dataset, capsys):
    data = default_dataset
    sensor, depth = data.sensor, 600.0
    width = 2 * depth * np.tan(np.radians(13.0))
    assert exercises.check_footprint_width(width, sensor, depth, data.scans[::50]) and said(capsys) == "correct"
    for wrong in (None, width / 2, 2 * depth * np.sin(np.radians(13.0)), 2 * depth * np.tan(13.0)):
        assert not exercises.check_footprint_width(wrong, sensor, depth) and said(capsys) == "not yet"
