"""The Risley-prism sensor (issue 60, items 1 and 6): its rays lie in the field of view and fill it within a
scan, each point carries its time and is cast from the pose of that time, a deskew with the known motion puts
the smeared scan back on the surface, bad settings are refused with their limit, and the fan is unchanged."""

import numpy as np
import pytest

from helpers.__main__ import main
from helpers.config.bounds import MAX_RAYS_PER_SCAN
from helpers.config.files import load_config
from helpers.config.sensor import MIN_FILL, field_fill
from helpers.config.tables import SensorConfig
from helpers.errors import SlamError
from helpers.geometry import transform_points
from helpers.sim.dataset import create_dataset
from helpers.sim.risley import ScanMotion, ray_times, risley_directions, scan_motion, standing
from helpers.sim.scene import GROUND, HeightField
from helpers.sim.sensor import Surface, cast_scans, poses_from_waypoints, ray_pattern
from helpers.slam.deskew import deskew

RISLEY = SensorConfig(pattern="risley", range_noise=0.0, dropout=0.0)


def off_nadir(directions: np.ndarray) -> np.ndarray:
    """Each ray's angle from the nadir, degrees."""
    return np.degrees(np.arccos(np.clip(-directions[..., 2], -1.0, 1.0)))


def deviations(directions: np.ndarray) -> np.ndarray:
    """The rays back as angle-space vectors (rho cos psi, rho sin psi), radians: what the fill is measured on."""
    rho = np.radians(off_nadir(directions))
    psi = np.arctan2(directions[..., 1], directions[..., 0])
    return np.stack([rho * np.cos(psi), rho * np.sin(psi)], axis=-1)


def sloped_field(slope=0.3, half=400.0, cell=4.0):
    """The plane z = slope * x: a smear along x moves points off it, as it would not off level ground."""
    n = int(2 * half / cell) + 1
    x = -half + cell * np.arange(n)
    z = np.tile(slope * x, (n, 1))  # rows are y, columns x
    return HeightField(-half, -half, cell, z, np.full((n, n), GROUND, np.uint8), np.ones((n, n), bool))


# Geometry ------------------------------------------------------------------------


def test_every_ray_lies_within_the_field_of_view_and_reaches_its_edge():
    for sensor in (RISLEY, SensorConfig(pattern="risley", field_of_view=38.4, prism_rpm=(20_000.0, -12_413.0))):
        rays = risley_directions(sensor, np.array([0.0, 0.37, 12.9, 3600.0]))  # scans later in a flight too
        np.testing.assert_allclose(np.linalg.norm(rays, axis=-1), 1.0)
        angles = off_nadir(rays)
        assert angles.max() <= sensor.field_of_view / 2 + 1e-9
        assert angles.max() > sensor.field_of_view / 2 - 0.1  # the rosette's petals reach the rim
        assert angles.min() < 1.0  # ... and pass the nadir


def test_a_survey_plans_its_strips_on_the_swath_the_rosette_covers():
    """The width across the track that a Risley scan's rays reach on flat ground 100 m below is the swath a
    survey spaces its strips by (helpers.sim.flight_plan.swath_width), not the fan's."""
    from helpers.sim.flight_plan import swath_width

    rays = risley_directions(RISLEY, np.array([0.0])).reshape(-1, 3)
    across = 100.0 * rays[:, 1] / np.abs(rays[:, 2])  # where each ray meets the ground, across the track
    assert swath_width(100.0, RISLEY) == pytest.approx(across.max() - across.min(), rel=0.01)
    assert swath_width(100.0, RISLEY) != pytest.approx(swath_width(100.0, SensorConfig()), rel=0.1)


def test_a_scan_holds_rate_times_period_points_that_fill_the_field():
    assert len(ray_pattern(RISLEY)) == RISLEY.rays_per_scan == 100_000 * 0.1
    avia = SensorConfig(pattern="risley", point_rate=240_000.0, scan_period=0.125)
    assert len(ray_pattern(avia)) == 30_000
    # Every scan of a flight, each from its own prism angles: most cells of the field's disc hold a ray.
    motion = scan_motion(
        poses_from_waypoints(np.column_stack([np.arange(20.0) * 2, np.zeros(20), np.full(20, 100)])), RISLEY
    )
    fills = [field_fill(deviations(rays), RISLEY.field_of_view) for rays in risley_directions(RISLEY, motion.start)]
    assert min(fills) >= MIN_FILL
    assert RISLEY.fill() == pytest.approx(fills[0])  # the config's check measures what is cast
    # The rosette goes on between scans (non-repetitive): the next scan's rays are others.
    first, second = risley_directions(RISLEY, motion.start[:2])
    assert np.abs(first - second).max() > 0.1


def test_times_lie_within_the_scan_and_increase():
    times = ray_times(RISLEY)
    assert times[0] == 0.0 and times[-1] < RISLEY.scan_period
    np.testing.assert_allclose(np.diff(times), 1 / RISLEY.point_rate)
    data = create_dataset(sensor=SensorConfig(pattern="risley", altitude=300.0), lazy=True)
    assert data.has_times and data.scans.has_times
    for index in (0, 7, len(data) - 1):
        scan, stamps = data.scans[index], data.times(index)
        assert len(stamps) == len(scan) > 0.9 * RISLEY.rays_per_scan  # a few dropouts, nothing off the map
        start = data.scans.motion.start[index]  # the scan's start on the flight's clock
        assert stamps.min() >= start and stamps.max() < start + RISLEY.scan_period and np.all(np.diff(stamps) > 0)
    assert data.scans.motion.start[7] > data.scans.motion.start[0]  # one clock across the flight
    # Cast lazily or all at once, scans and times are the same.
    batch = data.scans.cast(5, 8)
    assert all(np.array_equal(a, data.scans[i]) for i, a in zip(range(5, 8), batch.scans, strict=True))
    assert all(np.array_equal(a, data.times(i)) for i, a in zip(range(5, 8), batch.times, strict=True))


def test_the_pose_of_a_point_lies_between_its_scan_and_the_next_waypoint():
    waypoints = np.array([[0.0, 0.0, 100.0], [2.0, 0.0, 100.0], [2.0, 2.0, 100.0], [2.0, 2.0, 100.0]])
    motion = scan_motion(poses_from_waypoints(waypoints), RISLEY)
    np.testing.assert_allclose(motion.start, [0.0, 0.2, 0.4, 0.5])  # 2 m at 10 m/s; the hover lasts a scan
    np.testing.assert_allclose(motion.velocity[0], [10.0, 0.0, 0.0])  # along track, in the scan's own frame
    assert motion.yaw_rate[0] == pytest.approx(np.radians(45) / 0.2)  # the heading turns 45 deg to the next
    np.testing.assert_allclose(motion.velocity[2], 0.0)  # hovering
    np.testing.assert_allclose(motion.velocity[3], motion.velocity[2])  # the last goes on as the one before


# The drone moves during a scan ---------------------------------------------------------------


def after(seconds: float, velocity: np.ndarray, yaw_rate: float) -> np.ndarray:
    """The sensor's motion over ``seconds`` of a straight line and a steady turn: T_start_then."""
    motion = np.eye(4)
    c, s = np.cos(yaw_rate * seconds), np.sin(yaw_rate * seconds)
    motion[:2, :2] = [[c, -s], [s, c]]
    motion[:3, 3] = velocity * seconds
    return motion


@pytest.mark.parametrize(
    ("velocity", "yaw_rate"),
    [((10.0, 0.0, 1.0), 0.0), ((10.0, 0.0, 0.0), 0.3)],  # 1 m on and 10 cm up over a scan; or a 17 deg/s turn
    ids=["climbing", "turning"],
)
def test_a_scan_cast_while_moving_deskews_onto_the_surface_within_a_centimetre(velocity, yaw_rate):
    surface = Surface.from_height_field(sloped_field())
    start = np.eye(4)
    start[:3, 3] = [0.0, 0.0, 100.0]
    velocity = np.array(velocity)
    moving = ScanMotion(velocity[None], np.array([yaw_rate]), np.zeros(1))
    batch = cast_scans(surface, start[None], RISLEY, motion=moving)
    scan, times = batch.scans[0], batch.times[0]
    period = RISLEY.scan_period
    middle = start @ after(period / 2, velocity, yaw_rate)  # deskew's frame: the sensor's at the scan's middle
    deskewed = transform_points(deskew(scan, times / period, after(period, velocity, yaw_rate)), middle)

    def off_plane(points):
        return np.abs(points[:, 2] - 0.3 * points[:, 0])

    assert off_plane(deskewed).max() < 0.01
    assert np.linalg.norm(deskewed - batch.hits, axis=1).max() < 0.01  # each point where its ray hit
    # Read in the one frame of the scan's start, as it comes, the scan is smeared by the motion.
    assert np.linalg.norm(transform_points(scan, start) - batch.hits, axis=1).max() > 0.9
    # The same rays cast standing still at the middle pose see the same plane.
    still = cast_scans(surface, middle[None], RISLEY, motion=standing(1))
    assert off_plane(transform_points(still.scans[0], middle)).max() < 0.01


def test_each_point_is_cast_from_the_pose_of_its_time():
    surface = Surface.from_height_field(sloped_field())
    start = poses_from_waypoints(np.array([[5.0, -3.0, 120.0], [5.0, 2.0, 120.0]]))[0]  # heading along +y
    turning = ScanMotion(np.array([[10.0, 0.0, -2.0]]), np.array([1.0]), np.zeros(1))  # 1 rad/s to the left
    batch = cast_scans(surface, start[None], RISLEY, motion=turning)
    scan, times = batch.scans[0], batch.times[0]
    # The sensor's pose at each point's time: [Rz(t), (10 t, 0, -2 t)] after the scan's start.
    c, s, zero = np.cos(times), np.sin(times), np.zeros_like(times)
    rotation = np.stack(
        [np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, zero + 1], -1)], 1
    )
    in_start = np.einsum("nij,nj->ni", rotation, scan) + np.column_stack([10 * times, zero, -2 * times])
    np.testing.assert_allclose(transform_points(in_start, start), batch.hits, atol=2e-3)  # float32 rays
    rays = ray_pattern(RISLEY)[np.searchsorted(ray_times(RISLEY), times)]  # each point's ray, by its time
    np.testing.assert_allclose(scan / np.linalg.norm(scan, axis=1)[:, None], rays, atol=1e-6)


# Bad input: one line with the value and the limit ----------------------------------------------

BAD = [
    ("prism_rpm = [6000.0, -4000.0]", r"prism_rpm = \[6000.0, -4000.0\] .* reach only 25% .* the limit is 90%"),
    ("prism_rpm = [2000.0, -1313.0]", r"reach only \d+% of the field's cells in one scan .* the limit is 90%"),
    ("point_rate = 5000.0", r"point_rate = 5000 .* reach only \d+% .* the limit is 90%"),
    ("point_rate = 2e7", r"point_rate = 2e\+07 .* asks for 2e\+06 rays per scan .* the limit is 1,000,000 rays"),
    ("scan_period = 20.0", r"scan_period must be a positive number of seconds from 0.001 to 10, got 20.0"),
    ("field_of_view = 180.0", r"field_of_view must be a full cone angle in degrees from 1 to 170, got 180.0"),
    ("prism_rpm = [1e9, -1.0]", r"prism_rpm must be two rotation rates from -60000 to 60000 .* got \[1000000000.0"),
    ("pattern = 'raster'", r"pattern must be one of fan, risley, got 'raster'"),
]


@pytest.mark.parametrize(("line", "message"), BAD)
def test_bad_risley_settings_are_refused_when_the_file_is_read(tmp_path, line, message):
    path = tmp_path / "config.toml"
    path.write_text(f"[sensor]\n{line}\n" if line.startswith("pattern") else f"[sensor]\npattern = 'risley'\n{line}\n")
    with pytest.raises(SlamError, match=message) as caught:
        load_config(path)
    assert "\n" not in str(caught.value)


def test_the_fan_ignores_the_risley_settings_and_the_risley_the_fans():
    fan = SensorConfig(prism_rpm=(6000.0, -4000.0), point_rate=5000.0, scan_period=10.0)
    assert np.array_equal(ray_pattern(fan), ray_pattern(SensorConfig()))
    risley = SensorConfig(pattern="risley", azimuth=(-1.0, 1.0, 0.5))
    assert np.array_equal(ray_pattern(risley), ray_pattern(SensorConfig(pattern="risley")))
    at_limit = SensorConfig(pattern="risley", point_rate=MAX_RAYS_PER_SCAN / 0.1)
    assert at_limit.rays_per_scan == MAX_RAYS_PER_SCAN


def test_a_scan_longer_than_the_step_between_waypoints_is_one_error_line(tmp_path, capsys):
    waypoints = tmp_path / "slow.csv"
    waypoints.write_text("x,y\n" + "".join(f"{0.5 * i},0\n" for i in range(20)))  # 0.5 m apart: 0.05 s at 10 m/s
    config = tmp_path / "config.toml"
    config.write_text("[sensor]\npattern = 'risley'\naltitude = 300.0\n")
    message = r"scan_period = 0.1 s is longer than the 0.05 s between waypoints 0 and 1 .* the limit is 0.05 s"
    with pytest.raises(SlamError, match=message):
        create_dataset(waypoints_path=waypoints, sensor=load_config(config).sensor)
    code = main(["dataset", "--waypoints", str(waypoints), "--config", str(config), "--out", str(tmp_path / "out")])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "0.05 s" in lines[0], lines
    SensorConfig(pattern="risley", speed=5.0).check_waypoints(np.loadtxt(waypoints, delimiter=",", skiprows=1))
    SensorConfig().check_waypoints(np.loadtxt(waypoints, delimiter=",", skiprows=1))  # the fan takes no time


# The fan, as it was before the Risley sensor (figures taken from the version before it) -----------------


def test_the_default_fan_is_unchanged():
    pattern = ray_pattern(SensorConfig())
    assert pattern.shape == (8476, 3)
    np.testing.assert_allclose(pattern.sum(axis=0), [0.0, 0.0, -8.400137794593435e03], rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(pattern[4321], [0.00174532836589831, -0.11077495549065894, -0.9938439832614261])
    np.testing.assert_allclose(pattern[0], [-0.043619387365336, -0.22473695078520217, -0.9734426803862889])
    data = create_dataset(sensor=SensorConfig(), lazy=True)
    batch = data.scans.cast(0, 3)
    assert [len(scan) for scan in batch.scans] == [8399, 8389, 8406]
    assert batch.times is None and not data.has_times and data.times(0) is None
    first = batch.scans[0]
    np.testing.assert_allclose(
        first.sum(axis=0), [-1.8769975757598877e02, 3.6252401216924191e03, -5.0871431453857422e06], rtol=1e-6
    )
    np.testing.assert_allclose(first[0], [-26.86631202697754, -138.42132568359375, -599.568603515625], atol=1e-4)
    np.testing.assert_allclose(first[-1], [27.411466598510742, 141.23007202148438, -611.7346801757812], atol=1e-4)


RISLEY_KEYS = ["prism_rpm", "field_of_view", "point_rate", "scan_period", "speed"]
EXTREMES = ["0", "-1", "1", "1e308", "-1e308", "1e-300", "nan", "inf", "'x'", "true", "[1, 2]", "[0, 0]"]
EXTREMES += ["[60000, -60000]", "[nan, 1]", "[1e308, 1]", "[17000, -10307, 1]", "10_000_000"]


@pytest.mark.parametrize("value", EXTREMES)
@pytest.mark.parametrize("key", RISLEY_KEYS)
def test_every_risley_key_at_an_extreme_value_is_refused_in_one_line_or_castable(tmp_path, key, value):
    path = tmp_path / "config.toml"
    path.write_text(f"[sensor]\npattern = 'risley'\n{key} = {value}\n")
    try:
        sensor = load_config(path).sensor
    except SlamError as exc:
        assert "\n" not in str(exc) and key in str(exc)
    else:
        assert sensor.rays_per_scan <= MAX_RAYS_PER_SCAN and sensor.fill() >= MIN_FILL
        assert 0 < sensor.scan_period * sensor.speed < 1e4 and np.isfinite(ray_pattern(sensor)).all()
