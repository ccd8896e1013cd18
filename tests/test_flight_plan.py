"""Flight plans over a tile (helpers.sim.flight_plan and ``python -m helpers flight``), checked on a flat
field whose answers follow from the geometry: the swath, the strips' spacing, the turns, the units."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.cli.main import main
from helpers.config import SensorConfig
from helpers.errors import SlamError
from helpers.sim.flight_plan import ground_bounds, loop_plan, survey_plan, swath_width, write_plan
from helpers.sim.maps import MapFrame
from helpers.sim.scene import HeightField
from helpers.sim.waypoints import read_waypoints

GROUND = 30.0  # m, the flat field's height


def flat_field(width: float = 400.0, depth: float = 300.0) -> HeightField:
    ny, nx = int(depth) + 1, int(width) + 1
    z = np.full((ny, nx), GROUND)
    return HeightField(-width / 2, -depth / 2, 1.0, z, np.ones((ny, nx), np.uint8), np.ones((ny, nx), bool))


def test_the_swath_is_the_fan_across_the_track():
    assert swath_width(100.0, SensorConfig()) == pytest.approx(2 * 100.0 * np.tan(np.radians(13.0)))


def test_a_survey_flies_strips_along_the_longer_side_that_overlap_as_asked():
    field, height, overlap = flat_field(), 120.0, 0.3
    plan = survey_plan(field, height, overlap=overlap)
    assert np.allclose(plan[:, 2], GROUND + height)
    steps = np.linalg.norm(np.diff(plan[:, :2], axis=0), axis=1)
    assert steps.max() < 2.0 + 1e-6 and np.median(steps) == pytest.approx(2.0, abs=0.05)
    ys, counts = np.unique(np.round(plan[:, 1], 3), return_counts=True)
    strips = ys[counts > 0.75 * counts.max()]  # the strips: whole straight legs along the longer side (x, 400 m)
    swath = swath_width(height, SensorConfig())
    assert len(strips) >= 2 and np.allclose(np.diff(strips), swath * (1 - overlap), atol=1e-3)
    xmin, xmax, ymin, ymax = ground_bounds(field)
    across = plan[np.abs(plan[:, 0] - (xmin + xmax) / 2) < 1e-6]  # a cross line over every strip
    assert across[:, 1].min() < strips.min() and across[:, 1].max() > strips.max()
    # every waypoint, turns included, keeps its swath on the field
    assert plan[:, 0].min() > xmin and plan[:, 0].max() < xmax
    assert strips.min() - swath / 2 >= ymin - 1e-6 and strips.max() + swath / 2 <= ymax + 1e-6


def test_a_survey_too_wide_for_the_tile_is_refused_with_its_figures():
    with pytest.raises(SlamError, match=r"sweeps a \d+ m swath: the tile's ground \(99 x 79 m\)"):
        survey_plan(flat_field(100.0, 80.0), 150.0)


def test_a_loop_is_flown_as_many_laps_as_asked():
    field = flat_field()
    one, twice = loop_plan(field, 150.0, laps=1.0), loop_plan(field, 150.0, laps=2.2)
    assert len(twice) == round(2.2 * len(one))
    assert np.allclose(twice[: len(one)], one) and np.allclose(twice[len(one) : 2 * len(one)], one)


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan")])
def test_a_flight_not_above_the_ground_is_refused(bad):
    with pytest.raises(SlamError, match="above the ground must be a positive number"):
        loop_plan(flat_field(), bad)


def test_a_plan_is_written_in_the_tiles_own_coordinates_and_units(tmp_path):
    feet = 0.3048
    frame = MapFrame((1000.0, 2000.0), feet, feet, "US survey foot")
    plan = survey_plan(flat_field(), 120.0)
    write_plan(tmp_path / "flight.csv", plan, frame)
    read = read_waypoints(tmp_path / "flight.csv")
    assert np.allclose(frame.to_map(read), plan[:, :2], atol=1e-3)
    assert np.allclose(read[:, 2] * feet, plan[:, 2], atol=1e-3)


def test_the_flight_command_never_replaces_a_file(tmp_path, capsys):
    out = tmp_path / "flight.csv"
    out.write_text("mine")
    assert main(["flight", "no_such_tile.laz", "--height", "100", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == "mine"


def test_a_plan_keeps_to_the_tiles_ground_and_flies_over_its_lakes():
    """A tile cut along a diagonal (no points beyond it) and with a lake inside (no returns from the water):
    the plan stays off the cut corner, and crosses the lake as ground."""
    field = flat_field(400.0, 300.0)
    x, y = field.grid()
    field.valid[(x - field.x0) + (y - field.y0) < 150] = False  # the lower left corner: beyond the survey's edge
    field.valid[np.hypot(x - 60, y - 20) < 40] = False  # a lake
    xmin, xmax, ymin, ymax = ground_bounds(field)
    corner = (xmin - field.x0) + (ymin - field.y0)
    assert corner >= 150 - 2 * 5.0  # off the cut (within a planning cell)
    assert xmin < 20 and xmax > 100 and ymin < -20 and ymax > 60  # the lake lies inside
    for plan in (survey_plan(field, 100.0), loop_plan(field, 100.0)):
        cells = field.cell_of(plan[:, :2])
        assert (field.valid[cells] | (np.hypot(plan[:, 0] - 60, plan[:, 1] - 20) < 40)).all()


def test_waypoints_that_leave_a_tile_in_feet_are_named_in_feet():
    """The map's bounds in an error speak in the waypoint file's own units (here US survey feet)."""
    from helpers.sim.sensor import check_coverage, check_heights

    feet = 1200.0 / 3937.0
    frame = MapFrame((5000.0, 9000.0), feet, feet, "US survey foot")
    field = flat_field(100.0, 100.0)
    with pytest.raises(SlamError, match=r"x 4836\.0\.\.5164\.0 US survey ft"):
        check_coverage(field, np.array([[0.0, 0.0, 100.0], [400.0, 0.0, 100.0]]), frame)
    with pytest.raises(SlamError, match=r"reaches 98\.4 US survey ft"):
        check_heights(field, np.array([[0.0, 0.0, 10.0]]), frame)
