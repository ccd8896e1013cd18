"""A sparse tile keeps the scene's shape at a real tile's density; a low flight flies at the height asked for."""

import numpy as np
import pytest

from helpers.errors import SlamError
from helpers.sim.scene import default_scene
from helpers.sim.tiles import low_flight, sparse_tile


@pytest.fixture(scope="module")
def scene():
    return default_scene(size=(200.0, 160.0))


@pytest.fixture(scope="module")
def tile(scene):
    return sparse_tile(scene, density=1.5, size=120.0)


def test_sparse_tile_is_the_middle_square_of_the_scene_rebuilt_from_its_points(scene, tile):
    xmin, xmax, ymin, ymax = tile.bounds
    assert xmax - xmin == pytest.approx(120.0, abs=2) and ymax - ymin == pytest.approx(120.0, abs=2)
    assert abs((xmin + xmax) / 2) < 1.5 and abs((ymin + ymax) / 2) < 1.5  # the scene is centred on (0, 0)
    # every cell at most one cell from a point: its height is the scene's nearby, not invented
    x, y = tile.grid()
    cells = np.column_stack([x[tile.valid], y[tile.valid]])
    scene_z = scene.z[scene.cell_of(cells)]
    assert np.median(np.abs(tile.z[tile.valid] - scene_z)) < 0.5
    assert tile.valid.mean() > 0.95  # the holes of a sparse sampling are filled, not left without surface


def test_sparse_tile_is_repeatable_and_the_seed_changes_it(scene, tile):
    assert np.array_equal(sparse_tile(scene, density=1.5, size=120.0).z, tile.z)
    assert not np.array_equal(sparse_tile(scene, density=1.5, size=120.0, seed=1).z, tile.z)


def test_sparser_tiles_lose_detail(scene):
    dense, sparse = sparse_tile(scene, density=8.0, size=120.0), sparse_tile(scene, density=0.5, size=120.0)

    def error(t):  # mean height difference (m) from the scene, cell by cell
        gx, gy = t.grid()
        under = scene.z[scene.cell_of(np.column_stack([gx.ravel(), gy.ravel()]))].reshape(t.z.shape)
        return np.mean(np.abs(t.z - under))

    assert error(sparse) > error(dense)


def test_bad_tiles_are_refused(scene):
    for density, size in ((0.0, 100.0), (1.0, 0.0), (1.0, 500.0)):
        with pytest.raises(SlamError):
            sparse_tile(scene, density=density, size=size)


def test_low_flight_flies_the_fitted_loop_at_the_height_asked_for(tile):
    data = low_flight(tile, 150.0, scans=12)
    assert len(data) == 12 and len(data.scans) == 12
    ground = np.median(tile.z[tile.cell_of(data.waypoints[:, :2])])
    assert data.sensor.altitude - ground == pytest.approx(150.0)
    assert np.allclose(data.poses[:, 2, 3], data.sensor.altitude)
    steps = np.linalg.norm(np.diff(data.waypoints[:, :2], axis=0), axis=1)
    assert np.allclose(steps, 2.0, atol=0.01)  # the fitted loop's 2 m spacing
    scan = data.scans[3]  # cast when read, in the sensor frame: about 150 m below the sensor
    assert len(scan) > 1000 and np.median(scan[:, 2]) == pytest.approx(-150.0, abs=15)


def test_low_flight_refuses_a_flight_under_the_ground_or_of_one_scan(tile):
    for above, scans in ((0.0, 10), (-5.0, 10), (150.0, 1)):
        with pytest.raises(SlamError):
            low_flight(tile, above, scans=scans)
