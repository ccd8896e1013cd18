"""Loading maps and waypoints: real LAS/LAZ in feet, archives, MAT and CSV files, and bad files."""

import tarfile

import laspy
import numpy as np
import pytest
from scipy.io import savemat

import helpers
from helpers.config.tables import noise_seed_from_environment
from helpers.errors import SlamError
from helpers.sim.maps import height_field_from_points, read_map
from helpers.sim.waypoints import read_waypoints

FOOT = 0.3048


def test_autzen_is_read_in_metres_and_centred(autzen):
    tile = read_map(autzen)
    header = laspy.open(autzen).header
    assert tile.frame.unit_name == "foot" and tile.frame.scale_xy == FOOT
    assert len(tile.points) == header.point_count == 110_000
    extent_ft = np.asarray(header.maxs) - np.asarray(header.mins)
    np.testing.assert_allclose(np.ptp(tile.points, axis=0), extent_ft * FOOT, atol=1e-3)
    np.testing.assert_allclose(tile.points[:, :2].min(axis=0), -tile.points[:, :2].max(axis=0), atol=1e-6)
    np.testing.assert_allclose(tile.points[:, 2].min(), header.mins[2] * FOOT, atol=1e-3)


def test_the_tile_crs_records_travel_with_its_frame_and_to_tile_undoes_it(autzen):
    tile = read_map(autzen)
    vlrs = laspy.open(autzen).header.vlrs
    source = {v.record_id: v.record_data_bytes() for v in vlrs if v.user_id == "LASF_Projection"}
    assert {r.record_id: r.data for r in tile.frame.crs} == source  # WKT and GeoTIFF keys, as the tile has them
    assert [r.record_id for r in tile.frame.crs if r.is_wkt] == [2112]
    las = laspy.read(autzen)
    feet = np.column_stack([las.x, las.y, las.z])
    np.testing.assert_allclose(tile.frame.to_tile(tile.points), feet, atol=1e-6)


def test_tarball_is_unpacked_into_the_cache_not_beside_it(autzen, tmp_path):
    archive = tmp_path / "aerialMap.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(autzen, arcname="aerialMap/autzen_trim.laz")
    tile = read_map(archive)
    np.testing.assert_array_equal(tile.points, read_map(autzen).points)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["aerialMap.tar.gz", "cache"]
    assert list((tmp_path / "cache").rglob("autzen_trim.laz"))


def test_waypoints_in_the_tile_coordinates_follow_the_tile(autzen, tmp_path):
    tile = read_map(autzen)
    # two waypoints given in the tile's own feet, 100 ft apart around its centre
    centre = np.asarray(tile.frame.offset)
    feet = np.array([centre + [-50.0, 0.0], centre + [50.0, 0.0]])
    path = tmp_path / "gTruthWayPoints.mat"
    savemat(path, {"gTruthTraj": feet})
    data = helpers.create_dataset(
        autzen, path, helpers.SensorConfig(altitude=450.0, seed=noise_seed_from_environment())
    )
    np.testing.assert_allclose(data.waypoints[:, :2], [[-50 * FOOT, 0.0], [50 * FOOT, 0.0]], atol=1e-9)
    assert all(len(scan) > 1000 for scan in data.scans)


def test_tile_without_waypoints_gets_a_fitted_loop(autzen):
    data = helpers.create_dataset(
        autzen, sensor=helpers.SensorConfig(altitude=450.0, seed=noise_seed_from_environment())
    )
    xmin, xmax, ymin, ymax = data.surface.bounds
    assert len(data) > 100
    assert data.waypoints[:, 0].min() > xmin and data.waypoints[:, 0].max() < xmax
    assert data.waypoints[:, 1].min() > ymin and data.waypoints[:, 1].max() < ymax
    distance = data.surface_distances(data.scan_in_map(len(data) // 2))
    assert np.median(distance) < 0.05


def test_the_scans_of_a_real_tile_lie_on_its_points(autzen):
    """A sparse real tile (about 1.8 points per m², with a river where few
    pulses came back) becomes a surface the rays hit where the tile has points:
    no true hit is farther from a point of the tile than the filled gap
    allows, and the hits on cells that hold points lie on them as closely as
    the tile's own spacing."""
    from scipy.spatial import cKDTree

    from helpers.sim.dataset import MAP_CELL

    tile = read_map(autzen)
    sensor = helpers.SensorConfig(altitude=280.0, seed=noise_seed_from_environment())  # about 150 m above ground
    data = helpers.create_dataset(autzen, sensor=sensor)
    hits, field = data.map_points[::7].astype(float), data.surface  # a seventh of them: enough, and quick
    cell, max_gap = MAP_CELL, 3.0  # the height field's cell and its filled gap (height_field_from_points)
    # Horizontally: a filled cell is at most max_gap from a cell with points, and each point and hit is within
    # half a cell diagonal of its own cell's centre.
    across, _ = cKDTree(tile.points[:, :2]).query(hits[:, :2])
    assert across.max() <= max_gap + np.sqrt(2) * cell
    # Hits on cells that hold a point of the tile lie on its points.
    held = np.zeros(field.shape, bool)
    held[field.cell_of(tile.points)] = True
    on_points = held[field.cell_of(hits)]
    assert on_points.mean() > 0.5
    distance, _ = cKDTree(tile.points).query(hits[on_points])
    spacing = np.median(cKDTree(tile.points).query(tile.points, k=2)[0][:, 1])
    assert np.median(distance) < spacing
    assert np.percentile(distance, 95) < np.sqrt(2) * cell


def test_first_surface_height_field_keeps_the_highest_point_per_cell():
    points = np.array([[0.2, 0.2, 1.0], [0.7, 0.4, 5.0], [1.5, 0.5, 2.0], [0.5, 1.5, 3.0], [1.5, 1.5, 4.0]])
    field = height_field_from_points(points, np.zeros(5, np.uint8), cell=1.0)
    np.testing.assert_array_equal(field.z, [[5.0, 2.0], [3.0, 4.0]])
    assert field.x0 == 0.5 and field.y0 == 0.5 and field.valid.all()


def test_holes_are_filled_and_far_cells_left_empty():
    points = np.array([[0.5, 0.5, 1.0], [2.5, 0.5, 1.0], [20.5, 0.5, 1.0]])
    field = height_field_from_points(points, np.zeros(3, np.uint8), cell=1.0, max_gap=3.0)
    assert field.valid[0, 1] and field.z[0, 1] == 1.0  # a 1-cell hole is filled
    assert not field.valid[0, 10]  # 8 m from any point: no surface


def test_csv_waypoints_with_and_without_header(tmp_path):
    (tmp_path / "a.csv").write_text("x,y,z\n1,2,700\n3,4,700\n")
    (tmp_path / "b.csv").write_text("1.5,2.5\n3.5,4.5\n")
    np.testing.assert_array_equal(read_waypoints(tmp_path / "a.csv"), [[1, 2, 700], [3, 4, 700]])
    np.testing.assert_array_equal(read_waypoints(tmp_path / "b.csv"), [[1.5, 2.5], [3.5, 4.5]])


def test_shipped_mat_and_csv_hold_the_same_flight():
    csv = read_waypoints(helpers.DEFAULT_WAYPOINTS)
    mat = read_waypoints(helpers.DEFAULT_WAYPOINTS.with_suffix(".mat"))
    np.testing.assert_allclose(mat, csv, atol=1e-4)


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("noise.las", b"this is not a point cloud" * 20, "not a readable LAS/LAZ file"),
        ("empty.laz", b"", "not a readable LAS/LAZ file"),
        ("tile.xyz", b"1 2 3\n", "must be a .las, .laz or .tar.gz"),
        ("broken.tar.gz", b"\x1f\x8b\x08\x00garbage", "not a readable .tar.gz"),
    ],
)
def test_bad_map_files_are_refused(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(SlamError, match=message):
        read_map(path)


def test_truncated_las_is_refused_before_reading_the_body(tmp_path):
    header = laspy.LasHeader(point_format=3, version="1.2")
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(1000.0), np.arange(1000.0), np.zeros(1000)
    full = tmp_path / "full.las"
    las.write(full)
    cut = tmp_path / "cut.las"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    with pytest.raises(SlamError, match="truncated"):
        read_map(cut)


def test_tarball_without_a_tile(tmp_path):
    (tmp_path / "readme.txt").write_text("no map here")
    archive = tmp_path / "aerialMap.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(tmp_path / "readme.txt", arcname="readme.txt")
    with pytest.raises(SlamError, match=r"holds no \.las or \.laz"):
        read_map(archive)


def test_bad_waypoint_files(tmp_path):
    savemat(tmp_path / "wrong.mat", {"trajectory": np.zeros((3, 2))})
    with pytest.raises(SlamError, match=r"no variable gTruthTraj \(it holds \['trajectory'\]\)"):
        read_waypoints(tmp_path / "wrong.mat")
    (tmp_path / "text.csv").write_text("x,y\n1,two\n")
    with pytest.raises(SlamError, match="x,y or x,y,z numbers"):
        read_waypoints(tmp_path / "text.csv")
    savemat(tmp_path / "flat.mat", {"gTruthTraj": np.zeros((3, 4))})
    with pytest.raises(SlamError, match="N x 2 or N x 3"):
        read_waypoints(tmp_path / "flat.mat")
    with pytest.raises(SlamError, match="not found"):
        read_waypoints(tmp_path / "missing.csv")
