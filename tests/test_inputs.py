"""What a user may hand the package: TOML configurations and waypoint files
(CSV and MAT). Anything malformed, out of range or too big for a machine must
end in a SlamError (one `error:` line on the command line), anything valid
must load; nothing else may escape, however odd the input."""

import random

import numpy as np
import pytest
import scipy.sparse
from scipy.io import savemat

from helpers.__main__ import main
from helpers.config.bounds import MAX_RAYS_PER_FLIGHT, MAX_RAYS_PER_SCAN
from helpers.config.files import load_config
from helpers.config.tables import STAGE_TABLES, Config, SensorConfig, noise_seed_from_environment
from helpers.errors import SlamError
from helpers.sim.dataset import create_dataset
from helpers.sim.sensor import poses_from_waypoints, ray_pattern
from helpers.sim.waypoints import MAX_WAYPOINTS, read_waypoints

TINY_STEPS = "[sensor]\nazimuth = [-13, 13, 0.00001]\nelevation = [-2.5, 2.5, 0.00001]\n"


def _config(tmp_path, text: str):
    path = tmp_path / "config.toml"
    path.write_text(text)
    return load_config(path)


def _one_error_line(capsys, argv) -> str:
    """Run the command line in this process; it must fail with exit code 2 and one `error:` line."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


# Limits -------------------------------------------------------------------


def test_tiny_angle_steps_are_refused_with_the_memory_they_would_take(tmp_path, capsys):
    with pytest.raises(SlamError, match=r"asks for 1\.3e\+12 rays per scan \(about 189 TiB of ray buffers\); "):
        _config(tmp_path, TINY_STEPS)
    (tmp_path / "tiny.toml").write_text(TINY_STEPS)
    line = _one_error_line(capsys, ["dataset", "--config", str(tmp_path / "tiny.toml"), "--out", str(tmp_path / "o")])
    assert f"the limit is {MAX_RAYS_PER_SCAN:,} rays" in line
    assert not (tmp_path / "o").exists()


def test_a_fan_at_the_ray_limit_is_accepted_and_one_ray_more_is_not():
    at_limit = SensorConfig(azimuth=(-50.0, 49.9, 0.1), elevation=(-4.995, 4.995, 0.01))  # 1000 x 1000 rays
    assert at_limit.rays_per_scan == len(ray_pattern(at_limit)) == MAX_RAYS_PER_SCAN
    with pytest.raises(SlamError, match="rays per scan"):
        SensorConfig(azimuth=(-50.0, 50.0, 0.1), elevation=(-4.995, 4.995, 0.01))  # 1001 x 1000


def test_the_default_fan_is_far_below_the_limits():
    sensor = SensorConfig()
    assert sensor.rays_per_scan == len(ray_pattern(sensor)) == 326 * 26
    sensor.check_flight(MAX_RAYS_PER_FLIGHT // sensor.rays_per_scan)
    with pytest.raises(SlamError, match=r"scans of 8,476 rays ask for .* GiB of points\); the limit is 200,000,000"):
        sensor.check_flight(MAX_RAYS_PER_FLIGHT // sensor.rays_per_scan + 1)


def test_a_flight_too_long_for_memory_is_refused_before_casting(tmp_path):
    path = tmp_path / "long.csv"
    path.write_text("x,y\n" + "0,0\n" * 30_000)  # 30,000 scans of 8476 rays: 2.5e8 rays
    with pytest.raises(SlamError, match=r"30,000 scans of 8,476 rays ask for 2\.5e\+08 rays"):
        create_dataset(waypoints_path=path)


def test_more_waypoints_than_the_limit_are_refused(tmp_path):
    path = tmp_path / "many.csv"
    path.write_text("0,0\n" * (MAX_WAYPOINTS + 1))
    with pytest.raises(SlamError, match=f"holds {MAX_WAYPOINTS + 1:,} waypoints; the limit is {MAX_WAYPOINTS:,}"):
        read_waypoints(path)


# Configuration files ---------------------------------------------------------

CONFIG_ERRORS = [
    # wrong types
    ("[sensor]\naltitude = 'high'\n", "altitude must be a number"),
    ("[sensor]\naltitude = true\n", "altitude must be a number"),
    ("[sensor]\naltitude = [1, 2]\n", "altitude must be a number"),
    ("[sensor]\naltitude = {a = 1}\n", "altitude must be a number"),
    ("[sensor]\naltitude = 1979-05-27\n", "altitude must be a number"),
    ("[sensor]\nseed = 1.5\n", "seed must be a 64-bit integer"),
    ("[sensor]\nseed = '1'\n", "seed must be a 64-bit integer"),
    ("[sensor]\nazimuth = 5\n", "azimuth must be a list of 3 numbers"),
    ("[sensor]\nazimuth = [-13, 13]\n", "azimuth must be a list of 3 numbers"),
    ("[sensor]\nazimuth = ['a', 13, 0.1]\n", "azimuth must be a number"),
    ("[sensor]\nazimuth = [[-13], 13, 0.1]\n", "azimuth must be a number"),
    ("[registration]\nmetric = 3\n", "metric must be a string"),
    ("[features]\nneighbors = 60.0\n", "neighbors must be a 64-bit integer"),
    ("sensor = 5\n", r"\[sensor\] must be a table"),
    ("[[sensor]]\naltitude = 5\n", r"\[sensor\] must be a table"),
    ("[sensor.lidar]\naltitude = 5\n", r"unknown key\(s\) \['lidar'\]"),
    # out of range
    ("[sensor]\ndropout = 1\n", r"dropout must be a probability in \[0, 1\)"),
    ("[sensor]\ndropout = -0.1\n", "dropout must be a probability"),
    ("[sensor]\ndropout = nan\n", "dropout must be a probability"),
    ("[sensor]\nmax_range = 0\n", "max_range must be a positive number"),
    ("[sensor]\nmax_range = inf\n", "max_range must be a positive number"),
    ("[sensor]\nmax_range = nan\n", "max_range must be a positive number"),
    ("[sensor]\nrange_noise = inf\n", "range_noise must be zero or a positive number"),
    ("[sensor]\nrange_noise = -1\n", "range_noise must be zero or a positive number"),
    ("[sensor]\naltitude = nan\n", "altitude must be a finite number"),
    ("[sensor]\naltitude = -inf\n", "altitude must be a finite number"),
    ("[sensor]\nseed = -1\n", "seed must be a non-negative integer"),
    ("[sensor]\nazimuth = [-90, 0, 1]\n", "-89 < start <= stop < 89"),
    ("[sensor]\nazimuth = [0, 0, 0]\n", "a finite step > 0"),
    ("[sensor]\nazimuth = [-13, 13, nan]\n", "a finite step > 0"),
    ("[sensor]\nazimuth = [-13, 13, inf]\n", "a finite step > 0"),
    ("[sensor]\nelevation = [2.5, -2.5, 0.2]\n", "-89 < start <= stop < 89"),
    ("[registration]\nskip_frames = 0\n", "skip_frames must be an integer of at least 1"),
    ("[features]\ngrid_step = 0\n", "grid_step must be a positive number"),
    ("[features]\nmatch_ratio = nan\n", r"match_ratio must be in \(0, 1\]"),
    # huge
    (TINY_STEPS, "rays per scan"),
    ("[sensor]\nazimuth = [-13, 13, 1e-320]\n", "rays per scan"),
    ("[sensor]\nazimuth = [-13, 13, 0.00001]\n", r"asks for 6\.8e\+07 rays per scan"),
    ("[sensor]\naltitude = 1e400\n", "altitude must be a finite number"),
    ("[sensor]\naltitude = " + "9" * 400 + "\n", "altitude is too large a number"),
    ("[sensor]\nseed = 18446744073709551616\n", "seed must be a 64-bit integer"),
    ("[registration]\nmax_num_trials = 1_000_000_000_000\n", "max_num_trials must be an integer from 1 to 1,000,000"),
    ("[features]\nneighbors = 1000000\n", "neighbors must be an integer from 3 to 1,000"),
    ("[pose_graph]\nedges_back = 1000000000000000000\n", "edges_back must be an integer from 1 to 100"),
    ("a = " + "[" * 5000 + "]" * 5000 + "\n", "nests its values too deeply"),
    # not TOML
    ("[loop_closure]\nmax_attempts = 0\n", "max_attempts must be an integer from 1 to 100"),
    ("[registration]\nicp_max_iterations = 0\n", "icp_max_iterations must be an integer from 1 to 10,000"),
    ("[pose_graph]\nedge_sigma_deg = 0\n", "edge_sigma_deg must be a positive number"),
    # an earlier version's flat table
    ("[slam]\nedges_back = 2\n", r"\[slam\] table is now split by stage: edges_back -> \[pose_graph\] edges_back"),
    ("[slam]\n", r"\[slam\] table is now split by stage: use the tables"),
    ("[sensor\n", "not valid TOML"),
    ("[sensor]\naltitude = \n", "not valid TOML"),
    ("[sensor]\naltitude = 5\naltitude = 6\n", "not valid TOML"),
]


@pytest.mark.parametrize(("text", "message"), CONFIG_ERRORS)
def test_bad_configurations_are_refused(tmp_path, text, message):
    with pytest.raises(SlamError, match=message):
        _config(tmp_path, text)


def test_a_configuration_that_is_not_text_is_refused(tmp_path):
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\xff\xfe\x00[sensor]")
    with pytest.raises(SlamError, match="not valid TOML"):
        load_config(path)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("", Config()),
        ("[sensor]\n[features]\n[pose_graph]\n", Config()),
        ("[sensor]\naltitude = 500\n", Config(sensor=SensorConfig(altitude=500.0))),
        ("[sensor]\nazimuth = [-10, 10, 1]\n", Config(sensor=SensorConfig(azimuth=(-10.0, 10.0, 1.0)))),
        ("[sensor]\nmax_range = 1e5\ndropout = 0\n", Config(sensor=SensorConfig(max_range=1e5, dropout=0.0))),
        (
            "[registration]\nmax_num_trials = 1_000_000\n[pose_graph]\nedges_back = 100\n",  # at the limits
            Config().with_values(registration=dict(max_num_trials=1_000_000), pose_graph=dict(edges_back=100)),
        ),
    ],
)
def test_valid_configurations_load(tmp_path, text, expected):
    run_seed = {"seed": noise_seed_from_environment()}  # a file that sets no noise seed takes the entry point's
    assert _config(tmp_path, text) == expected.with_values(sensor=run_seed)


TOML_VALUES = [
    "0", "-1", "1", "3", "60", "0.5", "1e-320", "1e308", "inf", "-inf", "nan", "'x'", "true", "[]", "[1, 2]",
    "[-13, 13, 0.08]", "[-13, 13, 1e-5]", "[0, 0, 0]", "[1, 'a', 3]", "{a = 1}", "18446744073709551616",
    "'plane-to-plane'", "'cauchy'", "1979-05-27", "[[1], 2, 3]",
]  # fmt: skip


def test_random_configurations_load_or_raise_slam_error(tmp_path):
    keys = {table: list(vars(getattr(Config(), table))) + ["bogus"] for table in STAGE_TABLES}
    keys["other"] = ["x"]
    rng = random.Random(20240601)
    outcomes = {"loaded": 0, "refused": 0}
    for _ in range(400):
        lines = []
        for table in rng.sample(list(keys), rng.randint(1, 2)):
            lines.append(f"[{table}]")
            for key in rng.sample(keys[table], min(len(keys[table]), rng.randint(0, 3))):
                lines.append(f"{key} = {rng.choice(TOML_VALUES)}")
        try:
            config = _config(tmp_path, "\n".join(lines) + "\n")
        except SlamError:
            outcomes["refused"] += 1
        else:
            assert isinstance(config, Config)
            outcomes["loaded"] += 1
    assert min(outcomes.values()) > 20, outcomes  # both kinds were exercised


# Waypoint files ----------------------------------------------------------------

CSV_CASES = [
    ("", "holds no waypoints"),
    ("x,y\n", "holds no waypoints"),
    ("\n \n\t\n", "holds no waypoints"),
    ("1,2\n3\n", "lines have different numbers of columns"),
    ("1,2,3,4\n5,6,7,8\n", r"N x 2 or N x 3 .* shape \(2, 4\)"),
    ("1\n2\n", r"N x 2 or N x 3 .* shape \(2, 1\)"),
    ("x,y\n1,two\n", "every line must be x,y or x,y,z numbers"),
    ("1,2,\n", "every line must be x,y or x,y,z numbers"),
    ("1;2,3\n4;5,6\n", "every line must be x,y or x,y,z numbers"),  # the first line's comma: comma-separated
    ("x;y\n1,2\n", r"every line must be x,y or x,y,z numbers \(separated by semicolons\)"),
    ("x,y\n1,2,3\n", "lines have different numbers of columns"),
    ("x,y\nz,w\n1,2\n", "every line must be x,y or x,y,z numbers"),
    ("1,nan\n", "NaN or infinite"),
    ("1,inf\n", "NaN or infinite"),
    ("1e400,0\n", "NaN or infinite"),
]


@pytest.mark.parametrize(("text", "message"), CSV_CASES)
def test_bad_csv_waypoints_are_refused(tmp_path, text, message):
    path = tmp_path / "flight.csv"
    path.write_text(text)
    with pytest.raises(SlamError, match=message):
        read_waypoints(path)


def test_a_csv_of_binary_garbage_is_refused(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(SlamError):
        read_waypoints(path)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("x,y\n1,2\n", [[1, 2]]),  # one waypoint
        ("1,2,700\n", [[1, 2, 700]]),
        (" 1 , 2 \n\n3,4\n", [[1, 2], [3, 4]]),
        ("1;2\n3;4\n", [[1, 2], [3, 4]]),  # semicolons, as spreadsheets write in much of Europe
        ("1,2\n1,2\n1,2\n", [[1, 2], [1, 2], [1, 2]]),  # the drone hovers
    ],
)
def test_valid_csv_waypoints_load(tmp_path, text, expected):
    path = tmp_path / "flight.csv"
    path.write_text(text)
    np.testing.assert_array_equal(read_waypoints(path), expected)


@pytest.mark.parametrize(
    "text",
    [
        "x,y,z\n1,2,700\n3,4,710\n",
        "y,x,z\n2,1,700\n4,3,710\n",  # a file written y,x flies the same flight, not a transposed one
        "Z,Y,X\n700,2,1\n710,4,3\n",
        "x;y;z\n1;2;700\n3;4;710\n",
        " Y ; x ; Z \n2;1;700\n4;3;710\n",
        '"z","x","y"\n700,1,2\n710,3,4\n',
        "y_m,x_m,z_m\n2,1,700\n4,3,710\n",  # a unit after the name
        "X (ft);Y (ft);Z [ft]\n1;2;700\n3;4;710\n",
        "1;2;700\n3;4;710\n",  # no header: x, y, z in that order
    ],
)
def test_csv_columns_are_read_by_their_header_names(tmp_path, text):
    path = tmp_path / "flight.csv"
    path.write_text(text)
    np.testing.assert_array_equal(read_waypoints(path), [[1, 2, 700], [3, 4, 710]])


def test_csv_header_of_y_and_x_only_gives_xy(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_text("Y;X\n2;1\n4;3\n")
    np.testing.assert_array_equal(read_waypoints(path), [[1, 2], [3, 4]])


@pytest.mark.parametrize(
    ("header", "found"),
    [
        ("x,yy,z", "'x', 'yy', 'z'"),  # a misspelt name
        ("x,z", "'x', 'z'"),  # y missing
        ("x,y,z,time", "'x', 'y', 'z', 'time'"),  # a column that is not a coordinate
        ("x,y,x_m", "'x', 'y', 'x_m'"),  # x twice
        ("X;X;Y", "'X', 'X', 'Y'"),  # twice the same
        ("lon,lat", "'lon', 'lat'"),
    ],
)
def test_a_csv_header_naming_other_columns_is_one_error_naming_them(tmp_path, header, found):
    path = tmp_path / "flight.csv"
    path.write_text(f"{header}\n1,2,3,4\n")
    with pytest.raises(SlamError) as error:
        read_waypoints(path)
    message = str(error.value)
    assert f"flight.csv: the header names the columns {found};" in message
    assert "x and y, and optionally z" in message and "\n" not in message


MAT_CASES = [
    ("text", "abc", "it holds text"),
    ("cell array", np.array([[1.0, 2.0], "a"], dtype=object), "it holds a cell array"),
    ("sparse", scipy.sparse.csr_matrix(np.ones((3, 2))), "it holds a cell array or sparse matrix"),
    ("struct", {"x": 1.0, "y": 2.0}, "it holds a struct"),
    ("complex", np.ones((3, 2)) * 1j, "it holds complex numbers"),
    ("logical", np.array([[True, False], [False, True]]), "it holds true/false values"),
    ("empty", np.zeros((0, 2)), "holds no waypoints"),
    ("3-D", np.zeros((2, 2, 2)), "N x 2 or N x 3"),
    ("4 columns", np.zeros((3, 4)), "N x 2 or N x 3"),
    ("NaN", np.array([[0.0, np.nan]]), "NaN or infinite"),
    ("inf", np.array([[0.0, np.inf]]), "NaN or infinite"),
]


@pytest.mark.parametrize(("what", "value", "message"), MAT_CASES, ids=[c[0] for c in MAT_CASES])
def test_bad_mat_waypoints_are_refused(tmp_path, what, value, message):
    path = tmp_path / "flight.mat"
    savemat(path, {"gTruthTraj": value})
    with pytest.raises(SlamError, match=message):
        read_waypoints(path)


@pytest.mark.parametrize("content", [b"", b"MATLAB 5.0 MAT-file" + b"\x00" * 200, bytes(range(256)) * 8])
def test_a_damaged_mat_file_is_refused(tmp_path, content):
    path = tmp_path / "flight.mat"
    path.write_bytes(content)
    with pytest.raises(SlamError):
        read_waypoints(path)


@pytest.mark.parametrize(
    "value", [np.array([[1.0, 2.0]]), np.array([[1, 2], [3, 4]], np.int16), np.array([[7, 9]], np.uint8)]
)
def test_valid_mat_waypoints_load(tmp_path, value):
    path = tmp_path / "flight.mat"
    savemat(path, {"gTruthTraj": value})
    np.testing.assert_array_equal(read_waypoints(path), value.astype(float))


CSV_CELLS = ["1", "-2.5", "700", "nan", "inf", "", "x", "1e400", " 3 ", "1_0", "0x10", "1e-320", "--1"]


def test_random_csv_files_load_or_raise_slam_error(tmp_path):
    rng = random.Random(20240602)
    path = tmp_path / "flight.csv"
    outcomes = {"loaded": 0, "refused": 0}
    for _ in range(400):
        lines = ["x,y"] if rng.random() < 0.3 else []
        width = rng.randint(1, 4)
        for _ in range(rng.randint(0, 5)):
            cells = [rng.choice(CSV_CELLS[:3]) if rng.random() < 0.8 else rng.choice(CSV_CELLS) for _ in range(width)]
            lines.append(",".join(cells))
        path.write_text("\n".join(lines))
        try:
            points = read_waypoints(path)
        except SlamError:
            outcomes["refused"] += 1
        else:
            assert points.ndim == 2 and points.shape[1] in (2, 3) and len(points) > 0
            assert np.isfinite(points).all()
            outcomes["loaded"] += 1
    assert min(outcomes.values()) > 20, outcomes


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("empty.csv", b"", "empty.csv holds no waypoints"),
        ("header.csv", b"x,y\n", "header.csv holds no waypoints"),
        ("text.csv", b"1,two\n", "every line must be"),
        ("named.csv", b"x,yy,z\n1,2,3\n", "named.csv: the header names the columns 'x', 'yy', 'z';"),
    ],
)
def test_bad_waypoints_give_one_error_line(tmp_path, capsys, name, content, message):
    path = tmp_path / name
    path.write_bytes(content)
    line = _one_error_line(capsys, ["dataset", "--waypoints", str(path), "--out", str(tmp_path / "o")])
    assert message in line
    assert not (tmp_path / "o").exists()


def test_a_bad_mat_gives_one_error_line(tmp_path, capsys):
    path = tmp_path / "flight.mat"
    savemat(path, {"gTruthTraj": "north"})
    line = _one_error_line(capsys, ["dataset", "--waypoints", str(path), "--out", str(tmp_path / "o")])
    assert "gTruthTraj must be a matrix of real numbers" in line


# Headings at repeated waypoints ----------------------------------------------------


def _yaw_deg(poses):
    return np.degrees(np.arctan2(poses[:, 1, 0], poses[:, 0, 0]))


@pytest.mark.parametrize(
    ("xy", "yaw"),
    [
        ([[0, 0], [0, 10], [0, 10], [0, 10]], [90, 90, 90, 90]),  # hovering at the end keeps the heading
        ([[5, 5], [5, 5], [5, 5], [5, 6]], [90, 90, 90, 90]),  # hovering at the start takes the first one
        ([[0, 0], [0, 10], [0, 10], [0, 10], [10, 10]], [90, 90, 90, 0, 0]),  # hovering in the middle
        ([[3, 4], [3, 4], [3, 4]], [0, 0, 0]),  # never moves: heads along +x
        ([[3, 4]], [0]),  # one waypoint
    ],
)
def test_repeated_waypoints_keep_a_heading_instead_of_a_made_up_one(xy, yaw):
    waypoints = np.column_stack([np.asarray(xy, float), np.full(len(xy), 700.0)])
    poses = poses_from_waypoints(waypoints)
    assert np.isfinite(poses).all()
    np.testing.assert_allclose(_yaw_deg(poses), yaw, atol=1e-9)
    np.testing.assert_allclose(
        poses[:, :3, :3] @ poses[:, :3, :3].transpose(0, 2, 1), np.tile(np.eye(3), (len(xy), 1, 1))
    )


def test_one_waypoint_and_repeated_waypoints_make_a_dataset(tmp_path):
    one = tmp_path / "one.csv"
    one.write_text("x,y\n10,10\n")
    assert len(create_dataset(waypoints_path=one)) == 1
    hover = tmp_path / "hover.csv"
    hover.write_text("x,y\n0,0\n0,10\n0,10\n0,10\n")
    data = create_dataset(waypoints_path=hover)
    assert len(data) == 4 and np.isfinite(data.poses).all()
    np.testing.assert_array_equal(data.poses[2:], data.poses[[1, 1]])  # hovering: the same pose
    assert all(np.isfinite(scan).all() and len(scan) > 1000 for scan in data.scans)
