"""Stage 1 end to end on the embedded default scene."""

import numpy as np
import pytest

import helpers
from helpers.config.tables import SensorConfig
from helpers.errors import SlamError
from helpers.sim.scene import default_scene
from helpers.sim.trajectories import read_tum


def test_default_flight_is_a_closed_loop_with_overlap(default_dataset):
    xy = default_dataset.waypoints[:, :2]
    steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    np.testing.assert_allclose(steps, 2.0, atol=0.01)
    assert len(default_dataset) == 689
    # the last 120 m fly along the first 120 m again: on the same line, each
    # within half a spacing of an early waypoint
    nearest = np.linalg.norm(xy[-60:, None] - xy[None, :62], axis=2).min(axis=1)
    assert nearest.max() <= 1.0 + 1e-6
    np.testing.assert_allclose(xy[-60:, 1], -120.0, atol=1e-9)
    assert np.all(default_dataset.waypoints[:, 2] == 700.0)


def test_default_scene_heights_and_size():
    field = default_scene()
    xmin, xmax, ymin, ymax = field.bounds
    assert xmax - xmin >= 799 and ymax - ymin >= 599
    ground = np.median(field.z)
    assert 80.0 <= ground <= 120.0
    assert np.all(np.isin(np.unique(field.labels), np.arange(5)))


def test_scans_lie_on_the_surface_at_their_true_pose(default_dataset):
    sigma = default_dataset.sensor.range_noise
    for index in (0, 250, 500, 688):
        distance = default_dataset.surface_distances(default_dataset.scan_in_map(index))
        assert np.sqrt(np.mean(distance**2)) <= 1.1 * sigma
        assert distance.max() <= 5.5 * sigma


def test_a_wrong_pose_does_not_fit_the_surface(default_dataset):
    """The check above can fail: a scan moved by a pose 1 degree off lands off the surface."""
    scan = default_dataset.scans[250]
    pose = default_dataset.poses[250].copy()
    c, s = np.cos(np.radians(1.0)), np.sin(np.radians(1.0))
    pose[:3, :3] = pose[:3, :3] @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])  # a 1 degree roll
    distance = default_dataset.surface_distances(scan @ pose[:3, :3].T + pose[:3, 3])
    assert np.sqrt(np.mean(distance**2)) > 0.5


def test_ground_truth_map_is_the_union_of_noise_free_hits(default_dataset):
    assert len(default_dataset.map_points) == sum(len(s) for s in default_dataset.scans)
    distance = default_dataset.surface_distances(default_dataset.map_points[::997])
    assert distance.max() < 0.01


def test_same_seed_same_numbers_and_other_seed_other_noise(short_flight):
    a = helpers.create_dataset(waypoints_path=short_flight, sensor=SensorConfig(seed=3))
    b = helpers.create_dataset(waypoints_path=short_flight, sensor=SensorConfig(seed=3))
    c = helpers.create_dataset(waypoints_path=short_flight, sensor=SensorConfig(seed=4))
    assert all(np.array_equal(x, y) for x, y in zip(a.scans, b.scans, strict=True))
    assert np.array_equal(a.map_points, b.map_points) and np.array_equal(a.poses, b.poses)
    assert not np.array_equal(a.scans[0], c.scans[0])
    # without dropouts the same rays return, and the truth does not depend on the noise
    d = helpers.create_dataset(waypoints_path=short_flight, sensor=SensorConfig(seed=3, dropout=0.0))
    e = helpers.create_dataset(waypoints_path=short_flight, sensor=SensorConfig(seed=4, dropout=0.0))
    assert np.array_equal(d.map_points, e.map_points) and not np.array_equal(d.scans[0], e.scans[0])


def test_a_scan_does_not_depend_on_the_rest_of_the_flight(short_flight, tmp_path):
    """Scan i is seeded with (seed, i): flying a prefix gives the same first scans."""
    full = helpers.create_dataset(waypoints_path=short_flight)
    prefix = tmp_path / "prefix.csv"
    prefix.write_text("\n".join(short_flight.read_text().splitlines()[:11]))
    part = helpers.create_dataset(waypoints_path=prefix)
    # the headings of the last waypoint differ (one-sided difference), so compare the first 9 scans
    for i in range(9):
        np.testing.assert_array_equal(part.scans[i], full.scans[i])


def test_scene_is_the_same_bit_for_bit():
    a, b = default_scene(seed=11, size=(200.0, 150.0)), default_scene(seed=11, size=(200.0, 150.0))
    assert np.array_equal(a.z, b.z) and np.array_equal(a.labels, b.labels)
    assert not np.array_equal(a.z, default_scene(seed=12, size=(200.0, 150.0)).z)


def test_write_dataset_layout_and_round_trip(short_flight, tmp_path):
    data = helpers.create_dataset(waypoints_path=short_flight)
    out = helpers.write_dataset(data, tmp_path / "out")
    scans = sorted((out / "scans").glob("*.ply"))
    assert [p.name for p in scans[:2]] == ["000000.ply", "000001.ply"] and len(scans) == len(data)
    np.testing.assert_array_equal(read_ply(scans[7]), data.scans[7])  # exactly, float64
    stamps, poses = read_tum(out / "poses_gt.txt")
    np.testing.assert_array_equal(stamps, np.arange(len(data)))
    np.testing.assert_allclose(poses, data.poses, atol=1e-6)
    np.testing.assert_allclose(read_ply(out / "map_gt.ply"), data.map_points, atol=1e-4)
    # Open3D reads the files too
    import open3d as o3d

    assert len(o3d.io.read_point_cloud(str(scans[0])).points) == len(data.scans[0])


def test_failed_write_leaves_nothing_behind(short_flight, tmp_path, monkeypatch):
    data = helpers.create_dataset(waypoints_path=short_flight)
    calls = []

    def failing_write(path, points):
        calls.append(path)
        if len(calls) == 5:
            raise OSError("disk full")
        return original(path, points)

    import helpers.cli.outputs as dataset_module

    original = dataset_module.write_ply
    monkeypatch.setattr(dataset_module, "write_ply", failing_write)
    with pytest.raises(SlamError, match=r"^cannot write output folder .*/out: disk full$"):
        helpers.write_dataset(data, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())


def test_refuses_to_overwrite_a_foreign_folder(short_flight, tmp_path):
    data = helpers.create_dataset(waypoints_path=short_flight)
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    with pytest.raises(SlamError, match="not empty"):
        helpers.write_dataset(data, foreign)
    assert (foreign / "thesis.tex").read_text() == "precious"


def test_flight_off_the_map_is_refused(tmp_path):
    path = tmp_path / "away.csv"
    path.write_text("x,y\n0,0\n2,0\n900,0\n902,0\n")
    with pytest.raises(SlamError, match=r"2 of 4 waypoints leave the map"):
        helpers.create_dataset(waypoints_path=path)


def test_scans_beyond_max_range_are_reported_empty(short_flight):
    with pytest.raises(SlamError, match=r"40 of 40 scans came back empty"):
        helpers.create_dataset(waypoints_path=short_flight, sensor=SensorConfig(max_range=100.0))


def read_ply(path):
    """The (N, 3) points of a PLY file, read by Open3D's tensor reader, as float64."""
    import open3d as o3d

    return o3d.t.io.read_point_cloud(str(path)).point.positions.numpy().astype(np.float64)


def test_lazy_scans_are_the_same_points_and_truth_as_eager_ones(short_flight):
    eager = helpers.create_dataset(waypoints_path=short_flight)
    lazy = helpers.create_dataset(waypoints_path=short_flight, lazy=True)
    assert len(lazy) == len(eager) and lazy.truth is None  # nothing cast yet
    for i in (0, 7, len(eager) - 1, -1):
        np.testing.assert_array_equal(lazy.scans[i], eager.scans[i])
    assert [len(s) for s in lazy.scans[2:5]] == [len(s) for s in eager.scans[2:5]]
    np.testing.assert_array_equal(lazy.map_points, eager.map_points)  # cast once more, on first use
    np.testing.assert_array_equal(lazy.map_labels, eager.map_labels)
    with pytest.raises(IndexError):
        lazy.scans[len(eager)]
