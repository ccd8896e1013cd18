"""Where the commands write. A folder is replaced only when it holds nothing
but what the same command wrote there (its marker lists those files); a bad
place is refused before any work; what the system refuses while writing (a
full disk, a file size limit, a folder taken away) ends in one `error:` line
with nothing left behind; two writers replace one another whole; a writer
killed by SIGKILL leaves a temporary folder that the next write removes."""

import errno
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

import helpers
import helpers.cli.outputs
import helpers.config.files
import helpers.outdir
import helpers.paths
import helpers.sim.dataset
import helpers.sim.maps
from helpers.__main__ import main
from helpers.cli.outputs import DATASET_MARKER, RUN_MARKER
from helpers.errors import SlamError
from helpers.outdir import atomic_dir
from helpers.site import build as site_module

REPO = Path(__file__).resolve().parents[1]
OLD_SITE_MARKER = "Written by python -m helpers site: the next build replaces this folder.\n"  # before the file list


@pytest.fixture()
def tiny_flight(tmp_path):
    """Four waypoints over the default scene, as a CSV file."""
    path = tmp_path / "tiny.csv"
    xy = np.column_stack([np.arange(-4.0, 4.0, 2.0), np.full(4, 10.0)])
    np.savetxt(path, xy, delimiter=",", header="x,y", comments="")  # the header is the file's first line
    return path


@pytest.fixture()
def tiny_dataset(tiny_flight):
    return helpers.create_dataset(waypoints_path=tiny_flight)


@pytest.fixture()
def one_notebook(tmp_path, monkeypatch):
    """The book is one small notebook whose code cell imports Dash (as Open3D does) and prints 42."""
    import nbformat.v4

    folder = tmp_path / "notebooks"
    folder.mkdir()
    cells = [nbformat.v4.new_markdown_cell("# A page"), nbformat.v4.new_code_cell("import dash._jupyter\n6 * 7")]
    nbformat.write(nbformat.v4.new_notebook(cells=cells), folder / "01_page.ipynb")
    monkeypatch.setattr(site_module, "NOTEBOOKS", folder)
    return folder


def _one_error_line(capsys, argv) -> str:
    """Run the command line in this process: exit code 2 and one `error:` line."""
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


def _snapshot(folder: Path) -> dict:
    """Every path under ``folder`` with its bytes (None for a folder)."""
    return {p.relative_to(folder): None if p.is_dir() else p.read_bytes() for p in sorted(folder.rglob("*"))}


def _hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@contextmanager
def _unprivileged():
    """As root, permissions bind nobody: take the uid of ``nobody`` for the block."""
    if os.geteuid() != 0:
        yield
        return
    os.seteuid(65534)
    try:
        yield
    finally:
        os.seteuid(0)


# 1, 5: a place that is not ours is refused before anything is computed -------------------------------------------


def _place(kind: str, command: str, root: Path, monkeypatch) -> tuple[str, str]:
    """Builds a bad output place of ``kind`` under ``root``: (the --out argument, what the error says)."""
    marker = {"dataset": DATASET_MARKER, "run": RUN_MARKER, "site": site_module.MARKER}[command]
    out = root / "out"
    if kind == "a file":
        out.write_text("my notes")
        return str(out), f"output path {out} exists and is not a folder"
    if kind == "under a file":
        (root / "notes.txt").write_text("my notes")
        return str(root / "notes.txt" / "out"), f"lies under {root / 'notes.txt'}, which is a file"
    if kind == "the current folder's parent":
        (out / "here").mkdir(parents=True)
        monkeypatch.chdir(out / "here")
        return "..", "holds the current folder"
    if kind == "a user's folder":
        out.mkdir()
        (out / "thesis.tex").write_text("three years of work")
        return str(out), f"is not empty and holds no earlier {marker}: choose another"
    if kind == "a user's folder with an old marker":
        out.mkdir()
        (out / "thesis.tex").write_text("three years of work")
        old = {"dataset": "poses_gt.txt", "run": "metrics.json", "site": site_module.MARKER}[command]
        (out / old).write_text(OLD_SITE_MARKER if command == "site" else "mine")
        return str(out), f"was written by an older version, which left no list of its files ({marker}): delete it"
    if kind == "a mount point":
        return "/proc", "output folder /proc is a mount point, which cannot be replaced"
    raise ValueError(kind)


KINDS = ["a file", "under a file", "the current folder's parent", "a user's folder"]
KINDS += ["a user's folder with an old marker", "a mount point"]


@pytest.mark.parametrize("command", ["dataset", "run", "site"])
@pytest.mark.parametrize("kind", KINDS)
def test_a_bad_place_is_refused_before_any_work(tmp_path, monkeypatch, capsys, one_notebook, command, kind):
    def work(*args, **kwargs):
        raise AssertionError("the work started before the output place was checked")

    monkeypatch.setattr(helpers.sim.dataset, "create_dataset", work)
    monkeypatch.setattr(site_module, "_add_notebook", work)
    root = tmp_path / "place"
    root.mkdir()
    out, says = _place(kind, command, root, monkeypatch)
    before = _snapshot(root)
    args = [command, "--out", out] + (["--no-execute"] if command == "site" else [])
    assert says in _one_error_line(capsys, args)
    assert _snapshot(root) == before  # nothing of the user's touched, nothing of ours left


def test_a_read_only_parent_is_refused_before_any_work(capsys, monkeypatch, tiny_flight):
    monkeypatch.setattr(helpers.sim.dataset, "create_dataset", lambda *a, **k: pytest.fail("computed first"))
    root = Path(tempfile.mkdtemp(prefix="helpers-test-"))  # in /tmp: a folder nobody may enter
    try:
        root.chmod(0o755)
        (root / "ro").mkdir(mode=0o555)
        (root / "ro").chmod(0o555)
        with _unprivileged():
            line = _one_error_line(capsys, ["dataset", "--out", str(root / "ro" / "new" / "out")])
        assert line == f"error: output folder {root}/ro/new/out cannot be written: {root}/ro: Permission denied"
        assert list((root / "ro").iterdir()) == []
    finally:
        (root / "ro").chmod(0o755)
        subprocess.run(["rm", "-rf", str(root)], check=True)


# 1: a folder is replaced only while it holds nothing but what we wrote -----------------------------------------


def test_a_dataset_folder_with_a_users_file_added_is_refused(tmp_path, tiny_dataset):
    out = helpers.write_dataset(tiny_dataset, tmp_path / "ds")
    assert "scans/000003.ply" in (out / DATASET_MARKER).read_text().splitlines()
    helpers.write_dataset(tiny_dataset, out)  # our own folder: replaced
    (out / "scans" / "notes.txt").write_text("mine")
    with pytest.raises(SlamError, match=r"holds 1 file\(s\) this tool did not write \(scans/notes\.txt\)"):
        helpers.write_dataset(tiny_dataset, out)
    assert (out / "scans" / "notes.txt").read_text() == "mine"
    (out / "scans" / "notes.txt").unlink()
    helpers.write_dataset(tiny_dataset, out)
    assert sorted(p.name for p in out.iterdir()) == [
        DATASET_MARKER,
        "map_gt.ply",
        "poses_gt.txt",
        "scans",
        "sensor.toml",
    ]
    assert _hidden(tmp_path) == []


def _fake_run(n=4):
    """What write_run reads of a SLAM result: a config, two trajectories of ``n`` poses, their scans, a map."""
    from types import SimpleNamespace

    from helpers.config.tables import Config

    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n, dtype=float)
    points = np.random.default_rng(0).uniform(-50, 50, (200, 3)).astype(np.float32)
    return SimpleNamespace(
        config=Config(), poses_odometry=poses, poses_optimized=poses, indices=np.arange(n) * 2, map_points=points
    )


RUN_FILES = ["config.toml", "map.laz", "map.ply", "metrics.json"]
RUN_FILES += [f"trajectory_{name}.{ext}" for name in ("odometry", "optimized") for ext in ("csv", "kitti", "txt")]


def test_a_run_folder_holds_its_maps_and_trajectories(tmp_path, grid_tile):
    """TUM, KITTI and CSV trajectories, the map as PLY and LAZ (in the tile's coordinates), the truth's
    trajectories only when there is truth; the marker lists every file."""
    run = _fake_run()
    frame = helpers.sim.maps.read_map(grid_tile("tile.las", 60.0, 60.0, lambda x, y: x * 0 + 5.0)).frame
    out = helpers.cli.outputs.write_run(run, tmp_path / "run", {"n_scans": 4}, run.poses_optimized, frame=frame)
    truth = [f"trajectory_gt.{ext}" for ext in ("csv", "kitti", "txt")]
    assert sorted(p.name for p in out.iterdir()) == sorted([RUN_MARKER, *RUN_FILES, *truth])
    assert set((out / RUN_MARKER).read_text().splitlines()[1:]) >= set(RUN_FILES + truth)
    out = helpers.cli.outputs.write_run(run, out, {"n_scans": 4})  # no truth, no frame: replaces the earlier run
    assert sorted(p.name for p in out.iterdir()) == sorted([RUN_MARKER, *RUN_FILES])
    assert (out / "trajectory_optimized.csv").read_text().splitlines()[0] == "index,x,y,z,roll,pitch,yaw"


def test_an_old_site_is_left_for_the_user_to_delete(tmp_path, one_notebook):
    out = tmp_path / "html"
    out.mkdir()
    (out / site_module.MARKER).write_text(OLD_SITE_MARKER)
    (out / "index.html").write_text("an older book, or the user's page")
    with pytest.raises(SlamError, match=r"written by an older version.*delete it by hand"):
        site_module.build_site(out, execute=False)
    assert (out / "index.html").read_text() == "an older book, or the user's page"


# 4: what the system refuses while writing ends in one line, with nothing left behind ------------------------------


def test_a_full_disk_ends_in_one_error_line(tmp_path, capsys, monkeypatch, tiny_flight):
    real_write = helpers.cli.outputs.write_ply
    calls = []

    def full_disk(path, points):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        real_write(path, points)

    monkeypatch.setattr(helpers.cli.outputs, "write_ply", full_disk)
    root = tmp_path / "place"
    root.mkdir()
    out = root / "new" / "ds"
    line = _one_error_line(capsys, ["dataset", "--waypoints", str(tiny_flight), "--out", str(out)])
    assert line == f"error: cannot write output folder {out} (scans/000002.ply): No space left on device"
    assert list(root.iterdir()) == []  # no output, no temporary folder, not even the parent it made


def test_a_file_size_limit_ends_in_one_error_line(tmp_path, tiny_flight):
    """A real write error from the kernel: EFBIG under RLIMIT_FSIZE (Python ignores SIGXFSZ)."""
    out = tmp_path / "place" / "ds"

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    command = [sys.executable, "-m", "helpers", "dataset", "--waypoints", str(tiny_flight), "--out", str(out)]
    env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONDONTWRITEBYTECODE": "1"}
    done = subprocess.run(command, capture_output=True, text=True, preexec_fn=limit, env=env, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.splitlines() == [f"error: cannot write output folder {out}: File too large"]
    assert not (tmp_path / "place").exists()  # nor the parent it made


def test_an_out_through_dot_dot_is_the_folder_it_names(tmp_path, capsys, tiny_flight):
    """``x/new/..`` is ``x``: renaming it would fail with EBUSY."""
    x = tmp_path / "place" / "x"
    argv = ["dataset", "--waypoints", str(tiny_flight), "--out"]
    assert main([*argv, str(x)]) == 0
    first = (x / "poses_gt.txt").stat().st_mtime_ns
    time.sleep(0.01)
    assert main([*argv, f"{x}/new/.."]) == 0, capsys.readouterr().err
    assert (x / "poses_gt.txt").stat().st_mtime_ns != first  # replaced
    assert sorted(p.name for p in x.iterdir()) == [DATASET_MARKER, "map_gt.ply", "poses_gt.txt", "scans", "sensor.toml"]
    assert list((tmp_path / "place").iterdir()) == [x]


@pytest.mark.parametrize("exchange", ["refused", "unavailable"])
def test_a_failed_swap_puts_the_previous_output_back(tmp_path, tiny_dataset, monkeypatch, exchange):
    """Where the system exchanges the two folders in one step and refuses, nothing moved; where it cannot, the
    second of two renames fails and the first is undone."""
    out = helpers.write_dataset(tiny_dataset, tmp_path / "ds")
    before = _snapshot(out)
    real_rename = os.rename

    def busy(source, target=None):
        if target is None or ".helpers-partial." in str(source):
            raise OSError(errno.EBUSY, os.strerror(errno.EBUSY), str(target or out))
        real_rename(source, target)

    monkeypatch.setattr(helpers.outdir, "_exchange", busy if exchange == "refused" else lambda a, b: False)
    monkeypatch.setattr(helpers.outdir.os, "rename", busy)
    with pytest.raises(SlamError, match=r"^cannot write output folder .*/ds: Device or resource busy$"):
        helpers.write_dataset(tiny_dataset, out)
    monkeypatch.undo()
    assert _snapshot(out) == before and _hidden(tmp_path) == []


def test_any_oserror_from_a_command_is_one_error_line(capsys, monkeypatch, tmp_path):
    def unreadable(path):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), "config.toml")

    monkeypatch.setattr(helpers.config.files, "load_config", unreadable)
    line = _one_error_line(capsys, ["dataset", "--out", str(tmp_path / "ds")])
    assert line == "error: config.toml: Permission denied"


# 9: two writers at once -------------------------------------------------------------------------------------------

WRITER = """
import sys, time
from pathlib import Path
from helpers.outdir import atomic_dir
out, name, go = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
while not go.exists():
    time.sleep(0.001)
for i in range(int(sys.argv[4])):
    with atomic_dir(out, ".m") as work:
        (work / "a.txt").write_text(f"{name} {i}")
        (work / "sub").mkdir()
        (work / "sub" / "b.txt").write_text(f"{name} {i}")
"""


def test_two_writers_replace_one_another_whole(tmp_path):
    out, go = tmp_path / "place" / "out", tmp_path / "go"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    writers = [
        subprocess.Popen(
            [sys.executable, "-c", WRITER, str(out), name, str(go), "300"], env=env, stderr=subprocess.PIPE
        )
        for name in ("first", "second")
    ]
    time.sleep(1.0)  # both started and waiting
    go.touch()
    errors = [w.communicate(timeout=300)[1].decode() for w in writers]
    assert [w.returncode for w in writers] == [0, 0], errors
    assert sorted(p.name for p in out.parent.iterdir()) == ["out"]  # no temporary or previous folder left
    assert sorted(p.name for p in out.iterdir()) == [".m", "a.txt", "sub"]
    assert (out / "a.txt").read_text() == (out / "sub" / "b.txt").read_text()  # one writer's output, whole


# 10: the folder's mode, and what SIGKILL leaves ---------------------------------------------------------------------


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_an_output_folder_has_the_users_usual_mode(tmp_path, umask):
    previous = os.umask(umask)
    try:
        with atomic_dir(tmp_path / "out", ".m") as work:
            (work / "a.txt").write_text("a")
    finally:
        os.umask(previous)
    assert (tmp_path / "out").stat().st_mode & 0o777 == 0o777 & ~umask


KILLED = """
import sys, time
from helpers.outdir import atomic_dir
with atomic_dir(sys.argv[1], ".m") as work:
    (work / "half.txt").write_text("half")
    print("writing", flush=True)
    time.sleep(60)
"""


def test_the_temporary_folder_of_a_killed_writer_goes_at_the_next_write(tmp_path):
    place = tmp_path / "place"
    place.mkdir()
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    writer = subprocess.Popen([sys.executable, "-c", KILLED, str(place / "out")], env=env, stdout=subprocess.PIPE)
    assert writer.stdout.readline() == b"writing\n"
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    left = _hidden(place)
    assert len(left) == 1 and f".{writer.pid}." in left[0]
    # What is not a dead writer's of this host stays: a user's folder, another host's, a live process's.
    live = f".out.helpers-partial.{helpers.paths.host_name()}.{os.getpid()}.0123abcd"
    keep = [".out.notes", f".out.helpers-partial.otherhost.{writer.pid}.0123abcd", live, ".out.helpers-partial.x"]
    for name in keep:
        (place / name).mkdir()
    with atomic_dir(place / "out", ".m") as work:
        (work / "a.txt").write_text("a")
    assert sorted(p.name for p in place.iterdir()) == sorted([*keep, "out"])


SCRATCH = """
import time
from helpers.outdir import scratch_dir
with scratch_dir("helpers-book") as folder:
    (folder / "page.html").write_text("half")
    print("writing", flush=True)
    time.sleep(60)
"""


def test_the_scratch_folder_of_a_killed_book_build_goes_at_the_next_build(tmp_path, monkeypatch):
    env = {**os.environ, "PYTHONPATH": str(REPO), "TMPDIR": str(tmp_path)}
    writer = subprocess.Popen([sys.executable, "-c", SCRATCH], env=env, stdout=subprocess.PIPE)
    assert writer.stdout.readline() == b"writing\n"
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    left = [p.name for p in tmp_path.iterdir() if p.name.startswith(".helpers-book.")]
    assert len(left) == 1 and f".{writer.pid}." in left[0]
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    with helpers.outdir.scratch_dir("helpers-book") as folder:
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".helpers-book.")] == [folder.name]
    assert not folder.exists()


# 10: the book's kernels ---------------------------------------------------------------------------------------------

BOOK = """
import sys
from pathlib import Path
from helpers.site import build
build.NOTEBOOKS = Path(sys.argv[1])
from helpers.__main__ import main
sys.exit(main(["site", "--out", sys.argv[2]]))
"""


def test_the_book_runs_its_kernels_quietly_over_unix_sockets(tmp_path, one_notebook):
    """No "running over TCP without encryption" from the kernel, no "No handler found for comm target
    'dash'" from nbclient, and no socket file left anywhere."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = tmp_path / "html"
    command = [sys.executable, "-c", BOOK, str(one_notebook), str(out)]
    done = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert done.returncode == 0, done.stderr
    assert "TCP" not in done.stderr and "comm target" not in done.stderr, done.stderr
    assert "42" in (out / "01_page.html").read_text(encoding="utf-8")
    assert not list(tmp_path.glob("kernel*")) and not list(one_notebook.glob("kernel*"))
