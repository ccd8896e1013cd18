"""``python -m helpers flight TILE``: a flight plan over a tile, written as the waypoint CSV ``run`` reads."""

from __future__ import annotations

import argparse
from pathlib import Path

EXAMPLE = "example:\n  python -m helpers flight my_tile.laz --pattern survey --height 120 --out flight.csv"


def add_parser(sub) -> None:
    """The ``flight`` subcommand's arguments."""
    flight = sub.add_parser(
        "flight",
        help="plan a flight over a tile (a loop, or survey strips) and write its waypoints as CSV",
        description="Plan a flight over a tile: a loop over its middle, or parallel survey strips whose swaths "
        "overlap sideways and a cross line. The CSV holds x,y,z in the tile's own coordinates and units; "
        "python -m helpers run --map TILE --waypoints CSV flies it.",
        epilog=EXAMPLE,
    )
    flight.add_argument("tile", help=".las, .laz or .tar.gz holding one")
    flight.add_argument("--pattern", choices=("loop", "survey"), default="loop", help="default: loop")
    flight.add_argument("--height", type=float, required=True, help="metres above the median ground under the flight")
    flight.add_argument("--overlap", type=float, default=0.3, help="survey: side overlap of the swaths (default 0.3)")
    flight.add_argument("--laps", type=float, default=2.2, help="loop: laps flown (default 2.2)")
    flight.add_argument("--spacing", type=float, default=2.0, help="metres between waypoints (default 2)")
    flight.add_argument("--out", required=True, help="the CSV to write (refused if it exists)")


def run(args: argparse.Namespace) -> int:
    """Write the plan; an existing ``--out`` is never overwritten."""
    from helpers.errors import SlamError
    from helpers.sim.dataset import MAP_CELL
    from helpers.sim.flight_plan import loop_plan, survey_plan, write_plan
    from helpers.sim.maps import height_field_from_points, read_map
    from helpers.sim.sensor import check_coverage

    out = Path(args.out)
    if out.exists():
        raise SlamError(f"{out} exists: choose another name (a flight plan never replaces a file)")
    if not out.parent.is_dir():
        raise SlamError(f"{out.parent} is not a folder")
    tile = read_map(args.tile)
    field = height_field_from_points(tile.points, tile.labels, MAP_CELL)
    if args.pattern == "survey":
        waypoints = survey_plan(field, args.height, overlap=args.overlap, spacing=args.spacing)
    else:
        waypoints = loop_plan(field, args.height, laps=args.laps, spacing=args.spacing)
    check_coverage(field, waypoints, tile.frame)
    write_plan(out, waypoints, tile.frame)
    length = float(sum(((waypoints[1:, :2] - waypoints[:-1, :2]) ** 2).sum(axis=1) ** 0.5))
    print(f"{len(waypoints)} waypoints, {length / 1000:.2f} km, {args.height:g} m above the ground: written to {out}")
    return 0
