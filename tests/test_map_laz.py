"""Maps and trajectories where users' tools read them: ``map.laz`` back in the tile's own coordinates, units and
CRS records (or the run's local frame, said in the header), trajectories as KITTI lines and a CSV of angles."""

import struct

import laspy
import numpy as np
import pytest
from laspy.vlrs.vlrlist import VLRList

from helpers.sim.map_laz import FRAME_USER_ID, STEP_M, _quantisation, write_map_laz
from helpers.sim.maps import IDENTITY_FRAME, MapFrame, read_map
from helpers.sim.trajectories import CSV_HEADER, read_kitti, write_kitti, write_pose_csv

US_FOOT = 1200.0 / 3937.0
MM_IN_US_FEET = 0.001 / US_FOOT
# Oregon North (US survey feet), NAD83(HARN): the kind of projected CRS a real tile carries
WKT_US_FEET = (
    b'PROJCS["NAD83(HARN) / Oregon North (ft)",GEOGCS["NAD83(HARN)",DATUM["NAD83_High_Accuracy_Reference_Network",'
    b'SPHEROID["GRS 1980",6378137,298.257222101]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],'
    b'PROJECTION["Lambert_Conformal_Conic_2SP"],PARAMETER["standard_parallel_1",46],'
    b'PARAMETER["standard_parallel_2",44.33333333333334],PARAMETER["latitude_of_origin",43.66666666666666],'
    b'PARAMETER["central_meridian",-120.5],PARAMETER["false_easting",8202099.738],PARAMETER["false_northing",0],'
    b'UNIT["US survey foot",0.3048006096012192],AUTHORITY["EPSG","2913"]]\0'
)


def _tile_points(n=2000):
    """Random points of a 600 x 400 ft tile at Oregon-North-like coordinates, on a 0.01 ft grid."""
    rng = np.random.default_rng(7)
    x = 7_600_000 + rng.uniform(0, 600, n)
    y = 680_000 + rng.uniform(0, 400, n)
    return np.round(np.column_stack([x, y, 400 + rng.uniform(0, 50, n)]), 2)


def _write_tile(path, points, vlrs, evlrs=(), point_format=6):
    las = laspy.LasData(laspy.LasHeader(point_format=point_format, version="1.4"))
    las.header.scales, las.header.offsets = [0.01] * 3, [7_600_000.0, 680_000.0, 0.0]
    las.header.global_encoding.wkt = point_format >= 6
    las.header.vlrs.extend(vlrs)
    if evlrs:
        las.header.evlrs = VLRList(list(evlrs))
    las.x, las.y, las.z = points.T
    las.write(path)
    return path


def _geokeys(*keys):
    """A GeoKeyDirectoryTag: (key id, value) entries, each a short held in the directory."""
    words = [1, 1, 0, len(keys)] + [w for key, value in keys for w in (key, 0, 1, value)]
    return struct.pack(f"<{len(words)}H", *words)


def _read_back(path):
    las = laspy.read(path)
    return las.header, np.column_stack([las.x, las.y, las.z])


def _records(header, user_id="LASF_Projection"):
    records = list(header.vlrs) + list(header.evlrs or [])
    return {v.record_id: v.record_data_bytes() for v in records if v.user_id == user_id}


def test_a_map_in_us_feet_comes_back_in_feet_within_a_millimetre_with_the_tiles_wkt(tmp_path):
    points = _tile_points()
    wkt = laspy.VLR("LASF_Projection", 2112, "OGC WKT", WKT_US_FEET)
    tile = read_map(_write_tile(tmp_path / "tile.laz", points, [wkt]))
    assert tile.frame.unit_name == "US survey foot"
    write_map_laz(tmp_path / "map.laz", tile.points, tile.frame)
    header, written = _read_back(tmp_path / "map.laz")
    assert (header.version.major, header.version.minor, header.point_format.id) == (1, 4, 6)
    assert header.global_encoding.wkt
    assert np.abs(written - points).max() < MM_IN_US_FEET
    assert _records(header) == {2112: WKT_US_FEET}
    assert header.system_identifier == "SLAM map, tile CRS"
    description = _records(header, FRAME_USER_ID)[1].decode()
    assert "coordinate system and units (US survey foot)" in description
    assert read_map(tmp_path / "map.laz").frame.scale_xy == US_FOOT  # our own reader finds the same unit


def test_a_tile_with_only_geotiff_keys_keeps_them_in_point_format_1(tmp_path):
    points = _tile_points()
    keys = _geokeys((1024, 1), (3076, 9002))  # projected, in international feet
    tile_path = _write_tile(tmp_path / "tile.las", points, [laspy.VLR("LASF_Projection", 34735, "", keys)], (), 1)
    tile = read_map(tile_path)
    assert tile.frame.unit_name == "foot"
    write_map_laz(tmp_path / "map.laz", tile.points, tile.frame)
    header, written = _read_back(tmp_path / "map.laz")
    assert header.point_format.id == 1 and not header.global_encoding.wkt
    assert np.abs(written - points).max() < 0.001 / 0.3048
    assert _records(header) == _records(laspy.open(tile_path).header) == {34735: keys}


def test_a_wkt_held_in_an_evlr_is_copied(tmp_path):
    points = _tile_points(200)
    wkt = laspy.VLR("LASF_Projection", 2112, "OGC WKT", WKT_US_FEET)
    tile = read_map(_write_tile(tmp_path / "tile.las", points, [], [wkt]))
    write_map_laz(tmp_path / "map.laz", tile.points, tile.frame)
    header, written = _read_back(tmp_path / "map.laz")
    assert _records(header) == {2112: WKT_US_FEET} and header.global_encoding.wkt
    assert np.abs(written - points).max() < MM_IN_US_FEET


def test_the_real_tile_comes_back_in_its_feet_and_crs(autzen, tmp_path):
    tile = read_map(autzen)
    write_map_laz(tmp_path / "map.laz", tile.points, tile.frame)
    header, written = _read_back(tmp_path / "map.laz")
    source_header, source = _read_back(autzen)
    assert np.abs(written - source).max() < 0.001 / 0.3048
    wkt = {k: v for k, v in _records(source_header).items() if k == 2112}
    assert _records(header) == wkt and header.global_encoding.wkt


@pytest.mark.parametrize("frame", [None, IDENTITY_FRAME])
def test_a_run_without_a_tile_is_written_in_its_local_frame_and_says_so(tmp_path, frame):
    points = np.random.default_rng(1).uniform(-300, 300, (500, 3)).astype(np.float32)
    write_map_laz(tmp_path / "map.laz", points, frame)
    header, written = _read_back(tmp_path / "map.laz")
    np.testing.assert_allclose(written, points, atol=STEP_M)
    assert _records(header) == {} and not header.global_encoding.wkt
    assert header.system_identifier == "SLAM map, local frame"
    assert "local map frame: metres, no CRS" in _records(header, FRAME_USER_ID)[1].decode()


def test_a_tile_without_crs_goes_back_to_its_coordinates_and_says_it_had_none(tmp_path):
    frame = MapFrame((500_000.0, 4_000_000.0), 1.0, 1.0, "metre")
    points = np.random.default_rng(2).uniform(-100, 100, (100, 3))
    write_map_laz(tmp_path / "map.laz", points, frame)
    header, written = _read_back(tmp_path / "map.laz")
    np.testing.assert_allclose(written, points + [500_000.0, 4_000_000.0, 0.0], atol=STEP_M)
    assert "the tile had no CRS record" in _records(header, FRAME_USER_ID)[1].decode()


def test_an_empty_map_is_a_valid_file(tmp_path):
    write_map_laz(tmp_path / "map.laz", np.zeros((0, 3)), None)
    header, written = _read_back(tmp_path / "map.laz")
    assert header.point_count == 0 and written.shape == (0, 3)


def test_steps_grow_only_where_the_map_would_not_fit_32_bits():
    _, scales = _quantisation(np.array([[0.0, 0.0, 0.0], [100.0, 50.0, 10.0]]), IDENTITY_FRAME)
    np.testing.assert_array_equal(scales, [1e-4] * 3)
    feet = MapFrame((0.0, 0.0), 0.3048, 0.3048, "foot")
    assert _quantisation(np.zeros((1, 3)), feet)[1][0] == 1e-4  # 0.03 mm
    _, scales = _quantisation(np.array([[0.0, 0.0, 0.0], [1_000_000.0, 10.0, 10.0]]), IDENTITY_FRAME)
    np.testing.assert_array_equal(scales, [1e-3, 1e-3, 1e-4])  # a 1,000 km map: millimetres still


# trajectories -----------------------------------------------------------------------------------------------------


def _rotation(roll, pitch, yaw):
    """Rz(yaw) @ Ry(pitch) @ Rx(roll), degrees, from the elementary matrices."""
    r, p, y = np.radians([roll, pitch, yaw])
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _poses(angles, positions):
    poses = np.tile(np.eye(4), (len(angles), 1, 1))
    for pose, (roll, pitch, yaw), xyz in zip(poses, angles, positions, strict=True):
        pose[:3, :3], pose[:3, 3] = _rotation(roll, pitch, yaw), xyz
    return poses


def test_a_pose_with_known_angles_reads_back_from_the_csv(tmp_path):
    angles = [(5.0, -10.0, 30.0), (0.0, 0.0, 0.0), (-3.0, 2.5, -150.0)]
    positions = [(1.5, -2.25, 120.0), (0.0, 0.0, 0.0), (1234.5678, 9.0, -1.0)]
    write_pose_csv(tmp_path / "t.csv", _poses(angles, positions), [3, 7, 12])
    lines = (tmp_path / "t.csv").read_text().splitlines()
    assert lines[0] == CSV_HEADER == "index,x,y,z,roll,pitch,yaw"
    rows = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rows[:, 0], [3, 7, 12])
    np.testing.assert_allclose(rows[:, 1:4], positions, atol=1e-6)
    np.testing.assert_allclose(rows[:, 4:], angles, atol=1e-6)


def test_kitti_rows_reshape_to_the_poses(tmp_path):
    poses = _poses([(1.0, 2.0, 3.0), (-20.0, 5.0, 170.0)], [(10.0, 20.0, 30.0), (-4567.891234, 0.5, 99.0)])
    write_kitti(tmp_path / "t.kitti", poses)
    rows = np.loadtxt(tmp_path / "t.kitti")
    assert rows.shape == (2, 12)
    np.testing.assert_allclose(rows.reshape(-1, 3, 4), poses[:, :3, :], atol=1e-9)
    np.testing.assert_allclose(read_kitti(tmp_path / "t.kitti"), poses, atol=1e-9)
