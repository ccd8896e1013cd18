"""``run --scans DIR``: every scan format read back, the two steps (``dataset`` then ``run --scans``) agreeing
with ``run``, and messy folders (skipped scans, NaN points, mixed formats, empty, world frame)."""

import json
import logging
import shutil

import laspy
import numpy as np
import pytest

from helpers.cli.main import _parser, main
from helpers.cli.own_scans import _kept_gnss, read_truth, run_on_scans, wants_scans
from helpers.cli.scans import natural_key, open_scan_folder, read_scan
from helpers.errors import SlamError
from helpers.sim.gnss import GnssFixes
from helpers.sim.ply import write_ply
from helpers.sim.trajectories import read_tum

RNG = np.random.default_rng(7)


def scan(n=300, height=100.0):
    """A small synthetic scan in the sensor frame: ground ``height`` m below."""
    points = np.column_stack([RNG.uniform(-20, 20, n), RNG.uniform(-20, 20, n), -height + RNG.normal(0, 0.1, n)])
    return points


def parse_run(argv):
    """``argv`` parsed by the command line's own parser."""
    return _parser().parse_args(argv)


def write_pcd(path, points, times=None, binary=True):
    fields = "x y z" + (" time" if times is not None else "")
    k = 3 + (times is not None)
    table = points if times is None else np.column_stack([points, times])
    head = (
        f"# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {' '.join(['4'] * k)}\nTYPE {' '.join(['F'] * k)}\n"
        f"COUNT {' '.join(['1'] * k)}\nWIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {len(points)}\nDATA {'binary' if binary else 'ascii'}\n"
    )
    with open(path, "wb") as f:
        f.write(head.encode())
        if binary:
            f.write(table.astype("<f4").tobytes())
        else:
            np.savetxt(f, table, fmt="%.6f")


def write_las(path, points, times):
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    las.header.scales, las.header.offsets = [0.001] * 3, [0.0] * 3
    las.x, las.y, las.z = points.T
    las.gps_time = times
    las.write(path)


def test_binary_ply_as_dataset_writes_it_is_read_back_exactly(tmp_path):
    points = scan()
    write_ply(tmp_path / "a.ply", points)
    read, times = read_scan(tmp_path / "a.ply")
    assert read.dtype == np.float64 and np.array_equal(read, points) and times is None


def test_ascii_ply_with_times(tmp_path):
    points, t = scan(), np.linspace(0, 0.1, 300)
    head = "ply\nformat ascii 1.0\nelement vertex 300\nproperty float x\nproperty float y\nproperty float z\n"
    with open(tmp_path / "a.ply", "w") as f:
        f.write(
            head + "property double timestamp\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n"
        )
        np.savetxt(f, np.column_stack([points, t]), fmt="%.6f")
    read, times = read_scan(tmp_path / "a.ply")
    assert np.allclose(read, points, atol=1e-5) and np.allclose(times, t, atol=1e-6)


@pytest.mark.parametrize("binary", [True, False])
def test_pcd_with_times(tmp_path, binary):
    points, t = scan(), np.linspace(0, 0.1, 300)
    write_pcd(tmp_path / "a.pcd", points, t, binary)
    read, times = read_scan(tmp_path / "a.pcd")
    assert np.allclose(read, points, atol=1e-4) and np.allclose(times, t, atol=1e-6)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_and_laz_with_gps_time(tmp_path, suffix):
    points, t = scan(), np.linspace(100, 100.1, 300)
    write_las(tmp_path / f"a{suffix}", points, t)
    read, times = read_scan(tmp_path / f"a{suffix}")
    assert np.allclose(read, points, atol=1e-3) and np.allclose(times, t)


def test_npy_keeps_the_first_three_columns_and_kitti_bin(tmp_path):
    points = scan()
    np.save(tmp_path / "a.npy", np.column_stack([points, np.ones(300)]))
    assert np.array_equal(read_scan(tmp_path / "a.npy")[0], points)
    kitti = tmp_path / "kitti"
    kitti.mkdir()
    np.column_stack([points, np.ones(300)]).astype("<f4").tofile(kitti / "a.bin")
    assert np.array_equal(read_scan(kitti / "a.bin")[0], points.astype(np.float32))
    folder = open_scan_folder(kitti)
    assert folder.format == "KITTI" and folder[0].dtype == np.float64  # the estimator's type, whatever the file's
    np.ones(5, dtype="<f4").tofile(kitti / "b.bin")
    with pytest.raises(SlamError, match="16 bytes"):
        read_scan(kitti / "b.bin")


def test_files_come_in_natural_order_and_are_read_one_at_a_time(tmp_path):
    for k in (10, 2, 1):
        np.save(tmp_path / f"scan{k}.npy", scan(height=100.0 + k))
    (tmp_path / "notes.txt").write_text("not a scan")
    folder = open_scan_folder(tmp_path)
    assert [p.name for p in folder.files] == ["scan1.npy", "scan2.npy", "scan10.npy"]
    assert np.median(-folder[2][:, 2]) == pytest.approx(110.0, abs=0.1)
    assert natural_key("a9") < natural_key("a10")


def test_truth_as_tum_indices_tum_times_or_kitti(tmp_path):
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 0, 3] = [0.0, 2.0, 4.0]
    (tmp_path / "kitti.txt").write_text("\n".join(" ".join(map(str, p[:3].ravel())) for p in poses))
    assert np.allclose(read_truth(tmp_path / "kitti.txt", 3), poses)
    rows = np.column_stack([[1e9, 1e9 + 0.1, 1e9 + 0.2], poses[:, :3, 3], np.tile([0, 0, 0, 1.0], (3, 1))])
    np.savetxt(tmp_path / "times.txt", rows)
    assert np.allclose(read_truth(tmp_path / "times.txt", 3), poses)
    np.savetxt(tmp_path / "index.txt", np.column_stack([[0, 2], rows[[0, 2], 1:]]))
    truth = read_truth(tmp_path / "index.txt", 3)
    assert np.allclose(truth[[0, 2]], poses[[0, 2]]) and np.isnan(truth[1]).all()
    with pytest.raises(SlamError, match="one line per scan"):
        read_truth(tmp_path / "kitti.txt", 4)


def test_scan_options_need_scans_and_gnss_fixes_follow_the_kept_scans(tmp_path):
    assert not wants_scans(parse_run(["run", "--out", "x"]))
    with pytest.raises(SlamError, match="--truth, --sensor-height go with your own scans"):
        wants_scans(parse_run(["run", "--truth", "t.txt", "--sensor-height", "100", "--out", "x"]))
    for k in range(3):
        np.save(tmp_path / f"{k}.npy", scan())
    folder = open_scan_folder(tmp_path)
    folder.kept = [0, 2]  # scan 1 skipped
    fixes = _kept_gnss(GnssFixes(np.array([0, 1, 2]), np.arange(9.0).reshape(3, 3), [1.0, 1.0, 2.0]), folder, "g")
    assert fixes.indices.tolist() == [0, 1] and fixes.positions[1].tolist() == [6.0, 7.0, 8.0]


# --- messy folders --------------------------------------------------------------------------------------------


def test_an_empty_or_unreadable_scan_is_skipped_with_one_warning(tmp_path, caplog):
    for k in range(40):
        write_ply(tmp_path / f"{k:03d}.ply", scan())
    (tmp_path / "005.ply").write_bytes(b"")
    (tmp_path / "007.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\n")
    folder = open_scan_folder(tmp_path)
    with caplog.at_level(logging.WARNING):
        folder.survey()
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 2 and "005.ply" in warnings[0] and "007.ply" in warnings[1]
    assert len(folder) == 38 and folder.skipped == ["005.ply", "007.ply"]


def test_more_than_five_percent_skipped_is_an_error(tmp_path):
    for k in range(20):
        write_ply(tmp_path / f"{k:03d}.ply", scan())
    for k in (3, 4):
        (tmp_path / f"{k:03d}.ply").write_bytes(b"")
    with pytest.raises(SlamError, match="2 of the 20 scans"):
        open_scan_folder(tmp_path).survey()


def test_nan_and_infinite_points_are_dropped_and_counted(tmp_path):
    points = scan()
    points[:5, 0], points[5, 2] = np.nan, np.inf
    np.save(tmp_path / "0.npy", points)
    folder = open_scan_folder(tmp_path)
    folder.survey()
    assert folder.nonfinite == 6 and len(folder[0]) == 294 and np.isfinite(folder[0]).all()


def test_mixed_formats_an_empty_folder_and_a_world_frame_are_refused(tmp_path):
    with pytest.raises(SlamError, match="holds no scans"):
        open_scan_folder(tmp_path)
    np.save(tmp_path / "0.npy", scan())
    write_ply(tmp_path / "1.ply", scan())
    with pytest.raises(SlamError, match="mixes scan formats"):
        open_scan_folder(tmp_path)
    world = tmp_path / "world"
    world.mkdir()
    np.save(world / "0.npy", scan() + [500_000.0, 5_000_000.0, 0.0])
    with pytest.raises(SlamError, match="world coordinates"):
        open_scan_folder(world)


def test_the_command_refuses_a_bad_folder_with_one_error_line_before_any_work(tmp_path, capsys):
    args = parse_run(["run", "--scans", str(tmp_path / "none"), "--out", str(tmp_path / "out")])
    with pytest.raises(SlamError, match="no such folder"):
        run_on_scans(args)
    args = parse_run(["run", "--scans", str(tmp_path), "--waypoints", "w.csv", "--out", str(tmp_path / "out")])
    with pytest.raises(SlamError, match="--map and --waypoints"):
        run_on_scans(args)
    assert not (tmp_path / "out").exists()


# --- the two steps agree --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def two_steps(short_loop_csv, tmp_path_factory):
    """``dataset`` then ``run --scans`` of its scans and truth, and the plain ``run``, of the short loop."""
    root = tmp_path_factory.mktemp("two_steps")
    data, plain, scans = root / "D", root / "R1", root / "R2"
    assert main(["dataset", "--waypoints", str(short_loop_csv), "--out", str(data)]) == 0
    config = root / "config.toml"  # the dataset's sensor, and loops old enough to close on this short loop
    config.write_text((data / "sensor.toml").read_text() + "\n[loop_closure]\nsub_map_thresh = 5\n")
    config = str(config)
    assert main(["run", "--waypoints", str(short_loop_csv), "--config", config, "--out", str(plain)]) == 0
    argv = ["run", "--scans", str(data / "scans"), "--truth", str(data / "poses_gt.txt"), "--config", config]
    assert main([*argv, "--out", str(scans)]) == 0
    return data, plain, scans


def test_dataset_then_run_on_its_scans_gives_the_run_trajectory(two_steps):
    _, plain, scans = two_steps
    for name in ("optimized", "odometry"):
        stamps_1, poses_1 = read_tum(plain / f"trajectory_{name}.txt")
        stamps_2, poses_2 = read_tum(scans / f"trajectory_{name}.txt")
        assert np.array_equal(stamps_1, stamps_2)
        assert np.abs(poses_1[:, :3, 3] - poses_2[:, :3, 3]).max() <= 1e-6 + 1e-9
    m1, m2 = (json.loads((d / "metrics.json").read_text()) for d in (plain, scans))
    assert m1["config"] == m2["config"]
    assert m2["ate_rmse_optimized_m"] == pytest.approx(m1["ate_rmse_optimized_m"], abs=1e-6)
    assert m2["n_loop_closures"] == m1["n_loop_closures"] > 0 and m2["truth"].endswith("poses_gt.txt")


def test_a_messy_copy_runs_with_its_scans_skipped_and_points_counted(two_steps, tmp_path, caplog):
    data, _, _ = two_steps
    folder = tmp_path / "scans"
    folder.mkdir()
    for k in range(40):  # a short stretch: enough for the run, not for loops
        shutil.copy(data / "scans" / f"{k:06d}.ply", folder)
    (folder / "000020.ply").write_bytes(b"")
    points = read_scan(folder / "000030.ply")[0]
    points[:7] = np.nan
    write_ply(folder / "000030.ply", points)
    truth = tmp_path / "truth.txt"
    truth.write_text("".join((data / "poses_gt.txt").read_text().splitlines(keepends=True)[:40]))
    argv = ["run", "--scans", str(folder), "--truth", str(truth), "--out", str(tmp_path / "R")]
    with caplog.at_level(logging.WARNING):
        assert main([*argv, "--config", str(data / "sensor.toml")]) == 0
    assert any("000020.ply" in r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    metrics = json.loads((tmp_path / "R" / "metrics.json").read_text())
    assert metrics["scans"]["skipped"] == ["000020.ply"] and metrics["scans"]["n_nonfinite_points_dropped"] == 7
    assert metrics["n_scans"] == 39 and metrics["ate_rmse_optimized_m"] is not None
    stamps, _ = read_tum(tmp_path / "R" / "trajectory_optimized.txt")
    assert stamps.tolist() == [k + (k >= 20) for k in range(0, 39, 3)]  # stamps number the files, 000020 too


def test_without_truth_metrics_say_so_and_keep_the_trajectory(two_steps, tmp_path):
    data, _, _ = two_steps
    folder = tmp_path / "scans"
    folder.mkdir()
    for k in range(30):
        shutil.copy(data / "scans" / f"{k:06d}.ply", folder)
    argv = ["run", "--scans", str(folder), "--config", str(data / "sensor.toml"), "--out", str(tmp_path / "R")]
    assert main(argv) == 0
    metrics = json.loads((tmp_path / "R" / "metrics.json").read_text())
    assert metrics["truth"] is None and "ate_rmse_optimized_m" not in metrics
    assert len(metrics["trajectory_optimized_tum"]) == metrics["n_accepted"] and "trusted" in metrics
    assert not (tmp_path / "R" / "trajectory_gt.txt").exists()


def test_a_bad_scan_folder_is_one_error_line_on_the_command_line(tmp_path, capsys):
    (tmp_path / "scans").mkdir()
    assert main(["run", "--scans", str(tmp_path / "scans"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and not (tmp_path / "out").exists()


def test_scans_with_per_point_times_are_deskewed_with_the_last_motion(two_steps, tmp_path, monkeypatch):
    """Every accepted scan from the third on (the first step measures the motion) is deskewed with the
    odometry's last step, one period of it; times that all fall at one instant move nothing, so the
    trajectory is the one without times."""
    import helpers.slam.slam as slam_module

    data, _, _ = two_steps
    calls = []
    real = slam_module.deskew
    monkeypatch.setattr(slam_module, "deskew", lambda p, t, m: calls.append((len(p), t.copy(), m)) or real(p, t, m))
    runs = {}
    for name, with_times in (("plain", False), ("timed", True)):
        folder = tmp_path / name
        folder.mkdir()
        for k in range(24):
            points = read_scan(data / "scans" / f"{k:06d}.ply")[0]
            write_pcd(folder / f"{k:06d}.pcd", points, np.full(len(points), 7.0) if with_times else None)
        out = tmp_path / f"R-{name}"
        assert main(["run", "--scans", str(folder), "--config", str(data / "sensor.toml"), "--out", str(out)]) == 0
        runs[name] = read_tum(out / "trajectory_optimized.txt")[1]
    accepted = len(runs["timed"])
    assert len(calls) == accepted - 2 and all(np.all(t == 0.5) for _, t, _ in calls)
    assert all(m.shape == (4, 4) and np.linalg.norm(m[:3, 3]) > 0.5 for _, _, m in calls)  # a step of ~2 m a scan
    np.testing.assert_array_equal(runs["timed"], runs["plain"])
