"""Nothing silently wrong, nothing lost when a process dies (issue 63). Each
fault is built inside its test: a writer killed between the two renames of
its swap, an archive replaced under the same name, size and time, a damaged
or unwritable cache, memory running out, a full standard output, a cache
folder named with a literal ``~`` or from an empty ``HOME``, temporary files
of killed writers, a Turkish locale. The default run's cache and the edges
back's helper process have theirs in tests/test_cache.py and
tests/test_edges_worker.py."""

import errno
import logging
import os
import re
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import laspy
import numpy as np
import pytest

import helpers.paths
from helpers.__main__ import main
from helpers.cli.outputs import DATASET_MARKER
from helpers.errors import SlamError
from helpers.outdir import atomic_dir
from helpers.sim.maps import read_map

REPO = Path(__file__).resolve().parents[1]


def _python(code: str, *args, **kwargs) -> subprocess.CompletedProcess:
    """``code`` run by a fresh Python that imports this checkout's package."""
    env = {**os.environ, "PYTHONPATH": str(REPO), **kwargs.pop("env", {})}
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], env=env, timeout=300, **kwargs)


def _tree(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _tile(path: Path, height: float) -> Path:
    """A LAS tile of 30 x 30 points one metre apart at ``height``: tiles of other heights have the same size."""
    x, y = np.meshgrid(np.arange(30.0), np.arange(30.0))
    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.header.scales = [0.01, 0.01, 0.01]
    las.x, las.y, las.z = x.ravel(), y.ravel(), np.full(x.size, height)
    las.write(path)
    return path


def _archive(path: Path, tile: Path) -> Path:
    """``tile`` in a .tar.gz stored without compression: archives of same-size tiles have the same size."""
    with tarfile.open(path, "w:gz", compresslevel=0) as tar:
        tar.add(tile, arcname=f"map/{tile.name}")
    return path


# 1. A finished output is never lost ------------------------------------------------------------------------------

KILLED_BETWEEN_RENAMES = """
import os, sys
from pathlib import Path
import helpers.outdir
from helpers.outdir import atomic_dir
helpers.outdir._exchange = lambda a, b: False  # a file system without an exchange in one step: two renames
rename = os.rename
def rename_then_die(source, target):
    rename(source, target)
    if ".helpers-previous." in str(target):
        os._exit(9)  # SIGKILL, the OOM killer, a power cut: between the two renames
os.rename = rename_then_die
with atomic_dir(sys.argv[1], ".m") as work:
    (work / "a.txt").write_text("new")
"""


def _old_output(place: Path) -> dict:
    with atomic_dir(place / "out", ".m") as work:
        (work / "a.txt").write_text("old")
        (work / "sub").mkdir()
        (work / "sub" / "b.txt").write_text("old")
    return _tree(place / "out")


def test_an_output_a_killed_writer_set_aside_is_put_back_by_the_next_writer(tmp_path, caplog):
    place = tmp_path / "place"
    before = _old_output(place)
    assert _python(KILLED_BETWEEN_RENAMES, place / "out").returncode == 9
    left = sorted(p.name for p in place.iterdir())
    assert [name.split(".")[2] for name in left] == ["helpers-partial", "helpers-previous"]  # and no out
    with caplog.at_level(logging.WARNING, logger="helpers.outdir"):
        with atomic_dir(place / "elsewhere", ".m") as work:  # the next write anywhere in the same parent
            (work / "c.txt").write_text("c")
    assert sorted(p.name for p in place.iterdir()) == ["elsewhere", "out"]
    assert _tree(place / "out") == before
    (warning,) = [r.getMessage() for r in caplog.records]
    assert warning.startswith(f"output folder {place / 'out'} put back: a process (pid ")


def test_the_next_command_says_it_put_an_output_back_in_one_warning_line(tmp_path):
    place = tmp_path / "place"
    before = _old_output(place)
    assert _python(KILLED_BETWEEN_RENAMES, place / "out").returncode == 9
    waypoints = tmp_path / "tiny.csv"
    np.savetxt(waypoints, np.column_stack([np.arange(-4.0, 4.0, 2.0), np.full(4, 10.0)]), delimiter=",")
    command = [sys.executable, "-m", "helpers", "dataset", "--waypoints", waypoints, "--out", place / "ds"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": REPO})
    assert done.returncode == 0, done.stderr
    (line,) = done.stderr.splitlines()
    assert re.fullmatch(
        rf"warning: output folder {re.escape(str(place / 'out'))} put back: a process \(pid [0-9]+\) "
        "was killed while replacing it",
        line,
    ), line
    assert _tree(place / "out") == before and sorted(p.name for p in place.iterdir()) == ["ds", "out"]


@pytest.mark.parametrize("killed", ["before the swap", "after the exchange"])
def test_a_writer_killed_around_its_swap_leaves_an_output_in_place(tmp_path, killed):
    """Where the system exchanges two folders in one step, no moment of the swap leaves the place empty."""
    place = tmp_path / "place"
    before = _old_output(place)
    code = (
        "import os, sys, shutil\nimport helpers.outdir as o\nfrom helpers.outdir import atomic_dir\n"
        + (
            "o._swap = lambda work, target: os._exit(9)\n"
            if killed == "before the swap"
            else "shutil.rmtree = lambda *a, **k: os._exit(9)\n"
        )
        + "with atomic_dir(sys.argv[1], '.m') as work:\n    (work / 'a.txt').write_text('new')\n"
    )
    assert _python(code, place / "out").returncode == 9
    got = _tree(place / "out")
    assert got == before if killed == "before the swap" else (sorted(got), got["a.txt"]) == ([".m", "a.txt"], b"new")
    with atomic_dir(place / "elsewhere", ".m"):
        pass
    assert sorted(p.name for p in place.iterdir()) == ["elsewhere", "out"] and _tree(place / "out") == got


# 2, 7. The tile cache: keyed on content, checked when used, blamed for its own faults ------------------------------


def test_an_archive_replaced_with_the_same_size_and_time_is_unpacked_again(tmp_path):
    archive = _archive(tmp_path / "aerialMap.tar.gz", _tile(tmp_path / "tile.las", 100.0))
    first = read_map(archive)
    kept = archive.stat()
    _archive(tmp_path / "aerialMap.tar.gz", _tile(tmp_path / "tile.las", 250.0))  # cp -p, rsync -a, tar x
    os.utime(archive, ns=(kept.st_atime_ns, kept.st_mtime_ns))
    assert (archive.stat().st_size, archive.stat().st_mtime_ns) == (kept.st_size, kept.st_mtime_ns)
    assert np.allclose(first.points[:, 2], 100.0) and np.allclose(read_map(archive).points[:, 2], 250.0)


@pytest.mark.parametrize("damage", ["a flipped byte", "truncated"])
def test_a_damaged_copy_of_a_tile_in_the_cache_is_unpacked_again(tmp_path, damage, caplog):
    archive = _archive(tmp_path / "aerialMap.tar.gz", _tile(tmp_path / "tile.las", 100.0))
    good = read_map(archive)
    (copy,) = (tmp_path / "cache").rglob("tile.las")
    data = bytearray(copy.read_bytes())
    if damage == "a flipped byte":
        data[len(data) - 34 + 5] ^= 0x40  # the y of the last point (34-byte records of point format 3)
    else:
        del data[-1000:]
    copy.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING, logger="helpers.sim.archive"):
        again = read_map(archive)
    np.testing.assert_array_equal(again.points, good.points)
    warnings = [r.getMessage() for r in caplog.records if "assuming metres" not in r.getMessage()]  # the tile's
    (warning,) = warnings
    assert warning.startswith(f"the copy of aerialMap.tar.gz in the cache folder {tmp_path / 'cache'} is damaged")


def _full(monkeypatch, code):
    """The cache's disk full (ENOSPC) or read-only (EROFS) from the first file written into it."""
    real = os.open

    def refuse(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and Path(path).is_relative_to(helpers.paths.cache_dir()):
            raise OSError(code, os.strerror(code), str(path))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(helpers.paths.os, "open", refuse)


@pytest.mark.parametrize("fault", ["a file in its place", "full", "read-only", "HOME read-only"])
def test_an_unwritable_cache_is_named_as_such_not_the_archive(tmp_path, monkeypatch, capsys, fault):
    archive = _archive(tmp_path / "aerialMap.tar.gz", _tile(tmp_path / "tile.las", 100.0))
    cache = tmp_path / "cache"
    if fault == "a file in its place":
        cache.write_text("not a folder")
        why = f"{cache} is a file, not a folder"
    elif fault == "HOME read-only":
        monkeypatch.delenv("HELPERS_CACHE")
        monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
        monkeypatch.setenv("HOME", str(tmp_path / "home"))
        cache = tmp_path / "home" / ".cache" / "aerial-lidar-slam"
        _full(monkeypatch, errno.EROFS)
        why = "Read-only file system"
    else:
        _full(monkeypatch, errno.ENOSPC if fault == "full" else errno.EROFS)
        why = "No space left on device" if fault == "full" else "Read-only file system"
    assert main(["dataset", "--map", str(archive), "--out", str(tmp_path / "out")]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == (
        f"error: cannot unpack aerialMap.tar.gz into the cache folder {cache}: {why} ($HELPERS_CACHE sets another)"
    )
    assert not (tmp_path / "out").exists()


# 6. Out of memory ---------------------------------------------------------------------------------------------------

OPEN3D_OUT_OF_MEMORY = (
    "\x1b[1;31m[Open3D Error] (void open3d::t::geometry::RaycastingScene) Embree: out of memory\x1b[0;m"
)


def _exhaust(kind: str):
    if kind == "numpy":
        np.empty(1 << 60, np.uint8)  # a real _ArrayMemoryError: no machine has an exabyte
    if kind == "python":
        bytearray(1 << 62)
    raise RuntimeError(OPEN3D_OUT_OF_MEMORY)


@pytest.mark.parametrize("kind", ["numpy", "python", "open3d"])
def test_out_of_memory_is_one_error_line_naming_the_step_and_nothing_is_written(tmp_path, monkeypatch, capsys, kind):
    import helpers.slam.pipeline

    waypoints = tmp_path / "tiny.csv"
    np.savetxt(waypoints, np.column_stack([np.arange(-8.0, 8.0, 2.0), np.full(8, 10.0)]), delimiter=",")
    monkeypatch.setattr(helpers.slam.pipeline, "run_slam", lambda *args, **kwargs: _exhaust(kind))
    out = tmp_path / "place" / "run"
    assert main(["run", "--waypoints", str(waypoints), "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("error: out of memory while running SLAM: it asked for ")
    assert "\x1b" not in line and "Traceback" not in line
    assert ("it asked for 1.05e+06 TiB more with up to" in line) == (kind == "numpy")  # 2**60 bytes
    assert not (tmp_path / "place").exists()


# 7. A full standard output ------------------------------------------------------------------------------------------


def test_a_full_standard_output_is_named_and_the_dataset_is_whole(tmp_path):
    waypoints = tmp_path / "tiny.csv"
    np.savetxt(waypoints, np.column_stack([np.arange(-4.0, 4.0, 2.0), np.full(4, 10.0)]), delimiter=",")
    out = tmp_path / "ds"
    with open("/dev/full", "w") as full:
        command = [sys.executable, "-m", "helpers", "dataset", "--waypoints", waypoints, "--out", out]
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        done = subprocess.run(command, stdout=full, stderr=subprocess.PIPE, text=True, timeout=300, env=env)
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        f"error: cannot write to standard output: No space left on device; {out} was written in full"
    ]
    listed = (out / DATASET_MARKER).read_text().splitlines()[1:]
    assert listed and sorted(listed) == sorted(
        p.relative_to(out).as_posix() for p in out.rglob("*") if p.name != DATASET_MARKER
    )


# 8. The cache's place -----------------------------------------------------------------------------------------------


def test_a_cache_named_with_a_tilde_the_shell_did_not_expand_is_refused(tmp_path, monkeypatch):
    archive = _archive(tmp_path / "aerialMap.tar.gz", _tile(tmp_path / "tile.las", 100.0))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HELPERS_CACHE", "~/cache")
    with pytest.raises(SlamError, match=r"^\$HELPERS_CACHE=~/cache starts with ~, which the shell did not expand"):
        read_map(archive)
    assert not (tmp_path / "~").exists()


def test_an_empty_home_is_refused_not_taken_for_the_root(monkeypatch):
    monkeypatch.delenv("HELPERS_CACHE")
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", "")
    with pytest.raises(SlamError, match="HOME is empty"):
        helpers.paths.cache_dir()


def test_a_relative_cache_folder_is_taken_from_where_the_user_started(tmp_path, monkeypatch, caplog):
    """A kernel runs in notebooks/, started from the checkout: $PWD says where the user was."""
    (tmp_path / "notebooks").mkdir()
    monkeypatch.chdir(tmp_path / "notebooks")
    monkeypatch.setenv("PWD", str(tmp_path))
    monkeypatch.delenv("HELPERS_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", "relative-cache")
    with caplog.at_level(logging.WARNING, logger="helpers.paths"):
        assert helpers.paths.cache_dir() == tmp_path / "relative-cache" / "aerial-lidar-slam"
        assert helpers.paths.cache_dir() == tmp_path / "relative-cache" / "aerial-lidar-slam"
    (warning,) = [r.getMessage() for r in caplog.records]
    assert warning == (
        f"$XDG_CACHE_HOME=relative-cache is a relative path: the cache folder is "
        f"{tmp_path / 'relative-cache'} (from {tmp_path})"
    )


# 9. Leftovers of killed writers, and old entries ----------------------------------------------------------------------

KILLED_WHILE_WRITING = """
import os, sys, time
from pathlib import Path
from helpers.paths import write_atomically
def write(f):
    f.write(b"half a tile")
    f.flush()
    if sys.argv[2] == "killed":
        os._exit(9)  # SIGKILL, the OOM killer
    print("writing", flush=True)
    time.sleep(600)  # still at work
write_atomically(Path(sys.argv[1]), write)
"""


def test_the_temporary_files_of_killed_writers_go_at_the_next_start(tmp_path):
    archive = _archive(tmp_path / "aerialMap.tar.gz", _tile(tmp_path / "tile.las", 100.0))
    read_map(archive)
    cache = tmp_path / "cache"
    (tile_folder,) = (cache / "maps").iterdir()
    for place in (cache / "slam-0123456789abcdef.npz", tile_folder / "other.las"):
        assert _python(KILLED_WHILE_WRITING, place, "killed").returncode == 9
    command = [sys.executable, "-c", KILLED_WHILE_WRITING, cache / "slam-fedcba9876543210.npz", "at work"]
    live = subprocess.Popen(command, env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.PIPE)
    try:
        assert live.stdout.readline() == b"writing\n"
        hidden = sorted(p.name for p in cache.rglob(".*"))
        assert len(hidden) == 3
        read_map(archive)
        assert [p.name for p in cache.rglob(".*")] == [next(name for name in hidden if "fedcba" in name)]
    finally:
        live.kill()
        live.wait()


def test_the_least_recently_used_entries_go_when_the_cache_is_over_its_limit(tmp_path, monkeypatch):
    archives = {}
    for height in (100, 200, 300):
        archives[height] = _archive(tmp_path / f"map{height}.tar.gz", _tile(tmp_path / f"tile{height}.las", height))
    for age, height in ((2000, 100), (1000, 200)):  # unpacked long ago, 100 first
        read_map(archives[height])
        (folder,) = [p.parent for p in (tmp_path / "cache" / "maps").rglob(f"tile{height}.las")]
        for path in (folder, *folder.iterdir()):
            os.utime(path, (path.stat().st_mtime - age, path.stat().st_mtime - age))
    read_map(archives[100])  # used again: now the most recently used
    limit = 2 * (tmp_path / "tile100.las").stat().st_size + 1000  # two tiles and their records
    monkeypatch.setattr(helpers.paths, "CACHE_LIMIT", limit, raising=False)
    read_map(archives[300])  # over the limit: the least recently used goes
    assert sorted(p.name for p in (tmp_path / "cache").rglob("*.las")) == ["tile100.las", "tile300.las"]


# 10. Locale ---------------------------------------------------------------------------------------------------------


def _makefile_value(name: str) -> str:
    env = {k: v for k, v in os.environ.items() if k != name}
    rule = f"print-it: ; @echo $${name}"
    done = subprocess.run(
        ["make", "-s", "-f", "Makefile", f"--eval={rule}", "print-it"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_the_makefiles_openmp_wait_policy_is_read_in_a_turkish_locale(tmp_path):
    """libgomp compares the value in the locale Python set from the environment: in Turkish, I is not i's capital."""
    if shutil.which("localedef") is None or shutil.which("make") is None:
        pytest.skip("needs localedef (Debian's locales) and make")
    made = subprocess.run(["localedef", "-i", "tr_TR", "-f", "UTF-8", tmp_path / "tr_TR.UTF-8"], capture_output=True)
    if not (tmp_path / "tr_TR.UTF-8").exists():
        pytest.skip(f"the Turkish locale cannot be built here: {made.stderr.decode()}")
    value = _makefile_value("OMP_WAIT_POLICY")
    env = {"LOCPATH": str(tmp_path), "LC_ALL": "tr_TR.UTF-8", "OMP_DISPLAY_ENV": "true", "OMP_WAIT_POLICY": value}
    done = _python("import small_gicp", env=env, capture_output=True, text=True)  # small_gicp loads libgomp
    assert done.returncode == 0, done.stderr
    assert "OMP_WAIT_POLICY = 'PASSIVE'" in done.stderr and "Invalid value" not in done.stderr, done.stderr
