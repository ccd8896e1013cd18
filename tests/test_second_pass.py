"""A tester's second pass over bad inputs (issue 19): grid steps coarser than
the scans' footprint, and the cases it found beyond the issue's list. Each
input is built inside the test; each must end in one ``error:`` line, exit
code 2, and nothing written."""

import re
import time

import numpy as np
import pytest

import helpers
from helpers.__main__ import main
from helpers.config.tables import Config
from helpers.errors import SlamError
from helpers.slam.flight_fit import REFERENCE_HEIGHT, Flight, check_grid_steps, fit_to_flight, flight_of

SHORT_FLIGHT = "x,y\n" + "\n".join(f"{2.0 * i},-120" for i in range(30)) + "\n"  # 30 waypoints of the default loop


def _one_error_line(capsys, start: str) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {start}"), lines
    return lines[0]


# Grid steps against the footprint ---------------------------------------------


def test_a_map_grid_wider_than_the_footprint_allows_is_refused_before_the_run(tmp_path, capsys):
    """align_grid_step = 1000 used to give a 4-point map marked trusted."""
    flight = tmp_path / "flight.csv"
    flight.write_text(SHORT_FLIGHT)
    config = tmp_path / "coarse.toml"
    config.write_text("[map]\nalign_grid_step = 1000\n")
    start = time.perf_counter()
    code = main(["run", "--waypoints", str(flight), "--config", str(config), "--out", str(tmp_path / "o")])
    assert code == 2
    line = _one_error_line(capsys, "[map] align_grid_step = 1000 m is too coarse for this flight")
    assert re.search(r"cover 53\.\d m along the track .* the narrower, 10\.\d\d m", line)  # a fifth of the strip
    assert time.perf_counter() - start < 30  # the dataset is cast, SLAM never starts
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("table", "key"), [("features", "grid_step"), ("registration", "icp_grid_step"), ("map", "align_grid_step")]
)
def test_every_grid_step_is_held_to_a_fifth_of_the_narrow_side(table, key):
    flight = Flight(height=REFERENCE_HEIGHT, spacing=2.0, surface_cell=1.0, strip=50.0)  # 278 m across
    check_grid_steps(flight, Config().with_values(**{table: {key: 10.0}}))  # exactly a fifth: kept
    with pytest.raises(SlamError, match=rf"\[{table}\] {key} = 10.5 m .* at most 1/5 of the narrower, 10.00 m"):
        check_grid_steps(flight, Config().with_values(**{table: {key: 10.5}}))


def test_a_narrow_swath_is_the_footprint_that_counts():
    """A sensor that looks 1 degree to each side: the swath, not the strip, is the narrow side."""
    flight = Flight(height=600.0, spacing=2.0, surface_cell=1.0, strip=52.0)
    narrow = Config().with_values(sensor={"azimuth": (-1.0, 1.0, 0.05)})  # 20.9 m across
    with pytest.raises(SlamError, match=r"20\.9 m across .* 4\.19 m"):
        check_grid_steps(flight, narrow.with_values(map={"align_grid_step": 5.0}))


def test_the_default_the_low_and_the_real_flights_pass(default_dataset, grid_tile, autzen):
    # the default flight, fitted and as the reference has it
    flight = flight_of(default_dataset)
    check_grid_steps(flight, fit_to_flight(flight, Config())[0])
    check_grid_steps(flight, Config())
    # 150 m above a plane, as tests/test_cli.py flies it, fitted and with the reference's values
    tile = grid_tile("low.las", 150.0, 100.0, lambda x, y: 0.3 * np.sin(x / 7) * np.cos(y / 5))
    low = helpers.create_dataset(tile, sensor=helpers.SensorConfig(altitude=150.0), lazy=True)
    flight = flight_of(low)
    assert flight.height == pytest.approx(150.0, abs=1.0)
    check_grid_steps(flight, fit_to_flight(flight, Config())[0])
    check_grid_steps(flight, Config())
    # Autzen at the default altitude, and about 150 m above its ground
    for altitude in (700.0, 280.0):
        real = helpers.create_dataset(autzen, sensor=helpers.SensorConfig(altitude=altitude), lazy=True)
        flight = flight_of(real)
        check_grid_steps(flight, fit_to_flight(flight, Config())[0])


# Signals ----------------------------------------------------------------------


def test_sigterm_while_the_output_is_written_leaves_nothing(tmp_path):
    """SIGTERM (not only Ctrl-C) removes the temporary folder on the way out, at once."""
    import signal
    import subprocess
    import sys

    command = [sys.executable, "-m", "helpers", "dataset", "--out", str(tmp_path / "ds")]  # the default flight
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not any(".helpers-partial." in p.name for p in tmp_path.iterdir()):  # the scans are being written
        assert process.poll() is None and time.monotonic() < deadline, process.communicate()
        time.sleep(0.02)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 128 + signal.SIGTERM, err
    assert err.strip().splitlines() == ["error: terminated"]
    assert list(tmp_path.iterdir()) == []


# Inputs that are not what they claim -----------------------------------------


@pytest.mark.parametrize("option", ["--map", "--waypoints", "--config"])
@pytest.mark.parametrize("kind", ["a named pipe", "a folder", "a broken link or a loop of links", "a device or socket"])
def test_an_input_that_is_not_a_file_is_named_for_what_it_is(tmp_path, capsys, option, kind):
    """A FIFO must not hang the command, and a folder is not 'not found'."""
    import os

    suffix = {"--map": ".laz", "--waypoints": ".csv", "--config": ".toml"}[option]
    path = tmp_path / f"input{suffix}"
    if kind == "a named pipe":
        os.mkfifo(path)
    elif kind == "a folder":
        path.mkdir()
    elif kind == "a device or socket":
        path.symlink_to("/dev/zero")
    else:
        path.symlink_to(tmp_path / f"other{suffix}")
        (tmp_path / f"other{suffix}").symlink_to(path)
    start = time.perf_counter()
    assert main(["dataset", option, str(path), "--out", str(tmp_path / "o")]) == 2
    what = {"--map": "map file", "--waypoints": "waypoints file", "--config": "config file"}[option]
    assert _one_error_line(capsys, what).endswith(f"{path} is {kind}, not a file")
    assert time.perf_counter() - start < 10
    assert not (tmp_path / "o").exists()


def test_the_message_names_the_kind(tmp_path):
    from helpers.paths import input_file

    (tmp_path / "d.laz").mkdir()
    with pytest.raises(SlamError, match=r"^map file .*d\.laz is a folder, not a file$"):
        input_file(tmp_path / "d.laz", "map file")


def test_a_config_file_with_a_byte_order_mark_is_read(tmp_path):
    """Windows editors write a UTF-8 byte-order mark first; TOML is UTF-8 and the mark is not a statement."""
    from helpers.config.files import given_keys, load_config

    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf[sensor]\naltitude = 650.0\n")
    assert load_config(path).sensor.altitude == 650.0
    assert given_keys(path) == {("sensor", "altitude")}


def test_a_csv_number_with_an_underscore_is_an_error_not_a_value(tmp_path):
    """Python reads '1_20' as 120; a CSV reader must not."""
    from helpers.sim.waypoints import read_waypoints

    path = tmp_path / "flight.csv"
    path.write_text("x,y\n0,-120\n1_20,-120\n")
    with pytest.raises(SlamError, match=r"flight\.csv line 3: .* got '1_20,-120'"):
        read_waypoints(path)
    path.write_text("x_m,y_m\n0,-120\n2,-120\n")  # a header may hold underscores
    assert read_waypoints(path).shape == (2, 2)


def test_a_config_file_far_larger_than_a_configuration_is_refused_unread(tmp_path, capsys):
    from helpers.config.files import MAX_CONFIG_BYTES

    path = tmp_path / "huge.toml"
    with open(path, "wb") as f:
        f.write(b"[sensor]\naltitude = 700.0\n# padding\n")
        f.truncate(MAX_CONFIG_BYTES + 1)  # sparse: nothing kept on disk
    start = time.perf_counter()
    assert main(["dataset", "--config", str(path), "--out", str(tmp_path / "o")]) == 2
    assert "a configuration is a few kilobytes (the limit is 1 MiB)" in _one_error_line(capsys, "config file")
    assert time.perf_counter() - start < 5 and not (tmp_path / "o").exists()


def test_a_csv_larger_than_the_most_waypoints_take_is_refused_unread(tmp_path):
    from helpers.sim.waypoints import MAX_CSV_BYTES, read_waypoints

    path = tmp_path / "flight.csv"
    with open(path, "wb") as f:
        f.write(b"x,y\n0,-120\n2,-120\n")
        f.truncate(MAX_CSV_BYTES + 1)  # sparse
    import tracemalloc

    tracemalloc.start()
    with pytest.raises(SlamError, match=r"flight\.csv is 95\.4 MiB, more than 1,000,000 waypoints .* take"):
        read_waypoints(path)
    assert tracemalloc.get_traced_memory()[1] < 10 << 20  # never read in
    tracemalloc.stop()


def test_waypoints_under_the_ground_are_named_before_anything_is_cast(tmp_path, capsys):
    """The default scene's ground lies at 85 to 136 m: at 90 m some waypoints are inside its hills
    (it said 'scans came back empty', or cast scans from under the surface)."""
    flight = tmp_path / "flight.csv"
    flight.write_text("x,y,z\n" + "\n".join(f"{2.0 * i},-120,{700 if i < 5 else 30}" for i in range(30)) + "\n")
    assert main(["dataset", "--waypoints", str(flight), "--out", str(tmp_path / "o")]) == 2
    line = _one_error_line(capsys, "25 of 30 waypoints lie at or below the map's surface (indices 5-29;")
    assert "fly higher" in line and not (tmp_path / "o").exists()
    with pytest.raises(SlamError, match=r"waypoints lie at or below the map's surface"):
        helpers.create_dataset(sensor=helpers.SensorConfig(altitude=90.0))


# Output places ----------------------------------------------------------------


@pytest.mark.parametrize("inside", ["", "runs/mine", "maps"])
def test_an_output_inside_the_cache_is_refused(tmp_path, capsys, inside):
    """The cache may be deleted at any time (paths.cache_dir says so): a result written there would go with it."""
    out = tmp_path / "cache" / inside  # HELPERS_CACHE points there (tests/conftest.py)
    assert main(["dataset", "--out", str(out)]) == 2
    assert "lies inside the cache folder" in _one_error_line(capsys, f"output folder {out}")
    assert not (tmp_path / "cache" / "runs").exists()


def test_an_unexpanded_tilde_is_refused_not_made_into_a_folder(tmp_path, capsys, monkeypatch):
    """--out "~/runs/a" (quoted) made a folder named "~" in the current one."""
    monkeypatch.chdir(tmp_path)
    assert main(["dataset", "--out", "~/runs/a"]) == 2
    assert "which the shell did not expand" in _one_error_line(capsys, "output folder ~/runs/a starts with ~")
    assert not (tmp_path / "~").exists()


# LAS units ----------------------------------------------------------------------

WKT2_FEET = (  # WKT2 names the ellipsoid's unit (metres) before the coordinates' own (feet)
    'PROJCRS["NAD83 / Oregon GIC Lambert (ft)",BASEGEOGCRS["NAD83",DATUM["North American Datum 1983",'
    'ELLIPSOID["GRS 1980",6378137,298.257222101,LENGTHUNIT["metre",1]]],'
    'PRIMEM["Greenwich",0,ANGLEUNIT["degree",0.0174532925199433]]],CONVERSION["Lambert",METHOD["LCC"]],'
    'CS[Cartesian,2],AXIS["easting",east,LENGTHUNIT["foot",0.3048]],AXIS["northing",north,LENGTHUNIT["foot",0.3048]]]'
)
WKT1_METRES = 'PROJCS["x",GEOGCS["g",UNIT["degree",0.0174532925199433]],UNIT["metre",1.0]]'


def _tile_with_crs(path, geo_unit=None, wkt=None):
    """A 50 x 50 unit tile whose CRS records are a GeoTIFF linear-unit key (an EPSG code) and/or a WKT."""
    import laspy
    from laspy.vlrs.known import GeoKeyDirectoryVlr, GeoKeyEntryStruct, WktCoordinateSystemVlr

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = [0.01] * 3
    if geo_unit:
        keys = GeoKeyDirectoryVlr()
        keys.geo_keys_header.number_of_keys = 1
        key = GeoKeyEntryStruct()
        key.id, key.tiff_tag_location, key.count, key.value_offset = 3076, 0, 1, geo_unit  # ProjLinearUnitsGeoKey
        keys.geo_keys = [key]
        header.vlrs.append(keys)
    if wkt:
        header.vlrs.append(WktCoordinateSystemVlr(wkt))
    las = laspy.LasData(header)
    x, y = np.meshgrid(np.arange(50.0), np.arange(50.0))
    las.x, las.y, las.z = x.ravel(), y.ravel(), np.zeros(x.size)
    las.write(path)
    return path


def test_a_wkt2_tile_in_feet_is_read_in_feet(tmp_path):
    """The ellipsoid's LENGTHUNIT["metre"] came first and the tile was read as metres, 3.28 times too large."""
    from helpers.sim.maps import read_map

    tile = read_map(_tile_with_crs(tmp_path / "ft.las", wkt=WKT2_FEET))
    assert tile.frame.unit_name == "foot"
    assert np.ptp(tile.points[:, 0]) == pytest.approx(49 * 0.3048)


def test_crs_records_that_disagree_on_the_unit_are_refused(tmp_path):
    """GeoTIFF keys in feet (EPSG 9002) beside a WKT in metres: one is wrong, and which cannot be told."""
    from helpers.sim.maps import read_map

    with pytest.raises(SlamError, match="disagree on its unit: the GeoTIFF keys say foot, the WKT says metre"):
        read_map(_tile_with_crs(tmp_path / "mixed.las", geo_unit=9002, wkt=WKT1_METRES))
    assert read_map(_tile_with_crs(tmp_path / "same.las", geo_unit=9002, wkt=WKT2_FEET)).frame.unit_name == "foot"
