"""``data/aerialMap.tar.gz`` and ``data/gTruthWayPoints.mat`` are the default
flight in the reference's file formats: written by ``helpers.sim.reference_files``,
equal to what it writes now, and read back as the package's own scene and loop."""

import gzip
import tarfile
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat

import helpers
from helpers.errors import SlamError
from helpers.sim import reference_files as datafiles
from helpers.sim.dataset import MAP_CELL
from helpers.sim.maps import height_field_from_points, read_map

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def fresh():
    """File name -> bytes, as the package writes them now."""
    return datafiles.reference_files()


def test_the_committed_files_are_what_the_package_writes(fresh):
    # gzip's deflate may differ between zlib builds: the tar inside, tile bytes included, must not.
    committed_tar = gzip.decompress((DATA / datafiles.MAP_FILE).read_bytes())
    assert committed_tar == gzip.decompress(fresh[datafiles.MAP_FILE]), (
        "run: python -m helpers.sim.reference_files data"
    )
    assert (DATA / datafiles.WAYPOINTS_FILE).read_bytes() == fresh[datafiles.WAYPOINTS_FILE]


def test_writing_twice_gives_the_same_bytes(fresh):
    again = datafiles.reference_files()
    assert again == fresh


def test_the_archive_holds_one_tile_without_date_or_owner():
    with tarfile.open(DATA / datafiles.MAP_FILE, "r:gz") as tar:
        (member,) = tar.getmembers()
    assert member.name == datafiles.TILE_NAME and member.isfile()
    assert (member.mtime, member.uid, member.gid, member.uname, member.gname) == (0, 0, 0, "", "")


def test_the_waypoints_are_the_shipped_loop_exactly():
    mat = loadmat(DATA / datafiles.WAYPOINTS_FILE)
    assert [k for k in mat if not k.startswith("__")] == ["gTruthTraj"]
    np.testing.assert_array_equal(mat["gTruthTraj"], helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS))
    np.testing.assert_array_equal(
        helpers.read_waypoints(DATA / datafiles.WAYPOINTS_FILE), helpers.read_waypoints(helpers.DEFAULT_WAYPOINTS)
    )


def test_the_tile_reads_back_as_the_default_scene():
    """Through the loader any user's tile goes through: metres from the WKT,
    the map centred where the scene is, every cell its own height to within
    the tile's Z scale, every class the scene's."""
    tile = read_map(DATA / datafiles.MAP_FILE)
    assert tile.frame.offset == (0.0, 0.0) and tile.frame.scale_xy == 1.0 and tile.frame.unit_name == "metre"
    field = height_field_from_points(tile.points, tile.labels, MAP_CELL)
    scene = helpers.default_scene()
    assert (field.x0, field.y0, field.cell, field.shape) == (scene.x0, scene.y0, scene.cell, scene.shape)
    assert field.valid.all()
    np.testing.assert_array_equal(field.labels, scene.labels)
    assert np.abs(field.z - scene.z).max() <= datafiles.SCALES[2] / 2 + 1e-9


def test_a_file_it_did_not_write_is_refused_and_left_alone(tmp_path, capsys):
    foreign = tmp_path / datafiles.MAP_FILE
    with tarfile.open(foreign, "w:gz") as tar:
        tar.add(Path(__file__), arcname=datafiles.TILE_NAME)
    before = foreign.read_bytes()
    with pytest.raises(SlamError, match=r"was not written by helpers\.sim\.reference_files"):
        datafiles.write_reference_files(tmp_path)
    assert datafiles.main([str(tmp_path)]) == 2
    assert capsys.readouterr().err.startswith("error: ")
    assert foreign.read_bytes() == before and not (tmp_path / datafiles.WAYPOINTS_FILE).exists()


def test_its_own_files_are_replaced(tmp_path):
    for name in (datafiles.MAP_FILE, datafiles.WAYPOINTS_FILE):
        (tmp_path / name).write_bytes((DATA / name).read_bytes())
    assert datafiles.main([str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([datafiles.MAP_FILE, datafiles.WAYPOINTS_FILE])
