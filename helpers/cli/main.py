"""Command line: python -m helpers dataset|run|flight|site ... (installed: aerial-lidar-slam).

Errors in the input end in one line on stderr and exit code 2, never a
traceback, and never a half-written output folder. The output folder is
checked before any work starts (:func:`helpers.outdir.check_output_place`).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time

from helpers.cli import flight
from helpers.cli.memory import stage as _stage
from helpers.cli.own_scans import add_scan_arguments, run_on_scans, wants_scans
from helpers.cli.terminal import Parser, StreamError, example, report_run, say
from helpers.errors import SlamError


class Terminated(KeyboardInterrupt):
    """SIGTERM (a ``kill``, a job scheduler, a container stopping) raised as
    Ctrl-C is, so that what the command began is removed on the way out."""


class _Lines(logging.Formatter):
    """A log record as the command line's other messages: ``warning: ...`` on one line."""

    def format(self, record: logging.LogRecord) -> str:
        message = record.getMessage()
        if record.levelno >= logging.WARNING:
            message = " ".join(message.split())
        return f"{record.levelname.lower()}: {message}"


def main(argv=None) -> int:
    """The command line; SIGTERM is handled as Ctrl-C while it runs."""
    if threading.current_thread() is not threading.main_thread():  # signal handlers live in the main thread
        return _main(argv)
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _terminate(signum, frame):
    raise Terminated


def _main(argv=None) -> int:
    args = _parser().parse_args(argv)
    handler = logging.StreamHandler()
    handler.setFormatter(_Lines())
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, handlers=[handler])
    try:
        if args.command == "dataset":
            return _dataset(args)
        if args.command == "run":
            return _run(args)
        if args.command == "flight":
            return flight.run(args)
        if args.command == "site":
            from helpers.site import build_site

            with _stage("building the book"):
                index = build_site(args.out, execute=not args.no_execute)
            say(f"book written: {index}")
            return 0
    except SlamError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except StreamError as exc:  # the work is done and written; only its report is lost
        print(f"error: cannot write to standard output: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # the last line of defence: the stages turn the ones they expect into SlamError
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"error: {'terminated' if isinstance(exc, Terminated) else 'interrupted'}", file=sys.stderr)
        return 128 + (signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)
    return 1


DESCRIPTION = "Aerial lidar SLAM: simulate a flight's scans, run the SLAM on them, plan a flight, build the book."
EXAMPLES = {  # one command each, shown in its --help and together in the program's
    "dataset": "python -m helpers dataset --map my_tile.laz --waypoints flight.csv --out dataset",
    "run": "python -m helpers run --map my_tile.laz --waypoints flight.csv --out my_run",
    "run-scans": "python -m helpers run --scans my_scans --truth poses.txt --out my_run",
    "flight": flight.EXAMPLE.splitlines()[-1].strip(),
    "site": "python -m helpers site --out build/html",
}


def _parser() -> argparse.ArgumentParser:
    from helpers import __version__

    parser = Parser(prog="python -m helpers", description=DESCRIPTION, epilog=example(*EXAMPLES.values()))
    parser.add_argument("--version", action="version", version=f"aerial-lidar-slam-helpers {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log what each stage does")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{dataset,run,flight,site}")
    _dataset_parser(sub)
    _run_parser(sub)
    flight.add_parser(sub)
    _site_parser(sub)
    return parser


def _dataset_parser(sub) -> argparse.ArgumentParser:
    ds = sub.add_parser(
        "dataset",
        help="simulate the lidar scans of a flight over a map",
        description="Simulate the lidar scans of a flight over a map and write them with the true poses and map.",
        epilog=example(EXAMPLES["dataset"]),
    )
    _map_arguments(ds)
    ds.add_argument("--out", required=True, help="output folder (scans/, poses_gt.txt, map_gt.ply)")
    return ds


def _run_parser(sub) -> argparse.ArgumentParser:
    """The ``run`` subcommand; each set of its options is added by one call."""
    run = sub.add_parser(
        "run",
        help="run the whole SLAM pipeline on a simulated flight, or on your own scans (--scans DIR)",
        description="Simulate a flight's scans, or read your own (--scans DIR), and run the whole SLAM pipeline on "
        "them: odometry, loop closures, the pose graph, the map, graded against the truth when there is one. The "
        "last line says whether the result is trusted, in shape only (its scale unobserved) or not at all.",
        epilog=example(EXAMPLES["run"], EXAMPLES["run-scans"]),
    )
    _map_arguments(run)
    run.add_argument("--out", required=True, help="output folder (metrics.json, trajectories, map.laz, map.ply)")
    run.add_argument(
        "--reference-values",
        action="store_true",
        help="keep the configured values (by default the geometry-dependent ones the config file does not set "
        "are fitted to the flight's height and waypoint spacing: helpers.slam.flight_fit)",
    )
    _gnss_arguments(run)
    add_scan_arguments(run)
    return run


def _gnss_arguments(parser: argparse.ArgumentParser) -> None:
    gnss = parser.add_argument_group("GNSS")
    gnss.add_argument(
        "--gnss",
        metavar="FILE",
        help="GNSS positions per scan, map frame (.csv index,x,y,z or TUM .txt/.tum, t = scan index), added to "
        "the pose graph as GPS factors",
    )
    gnss.add_argument(
        "--gnss-sigma",
        metavar="H[,V]",
        help="sigma of a GNSS position, metres, horizontal[,vertical] (default: the [sensor] gnss sigmas)",
    )


def _site_parser(sub) -> argparse.ArgumentParser:
    site = sub.add_parser(
        "site",
        help="execute the notebooks and build them into a book that opens from disk",
        description="Execute the tutorial's notebooks and build them into an HTML book that opens from disk.",
        epilog=example(EXAMPLES["site"]),
    )
    site.add_argument("--out", default="build/html", help="output folder (default: build/html)")
    site.add_argument("--no-execute", action="store_true", help="export the notebooks as committed")
    return site


def _map_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", help=".las, .laz or .tar.gz holding one (default: the embedded scene)")
    parser.add_argument(
        "--waypoints",
        help=".mat with gTruthTraj, or .csv with columns x, y and optionally z, named in a header or in that "
        "order (default: a loop)",
    )
    parser.add_argument("--config", help="TOML file with a table per stage: [sensor], [features], [registration], ...")


def _dataset(args) -> int:
    from helpers.cli.outputs import DATASET_LEGACY_MARKER, DATASET_MARKER, write_dataset
    from helpers.config.files import load_config
    from helpers.outdir import check_output_place
    from helpers.sim.dataset import create_dataset

    check_output_place(args.out, DATASET_MARKER, DATASET_LEGACY_MARKER)
    config = load_config(args.config)
    start = time.perf_counter()
    with _stage("creating the dataset"):
        data = create_dataset(args.map, args.waypoints, config.sensor, progress=sys.stderr.isatty())
    with _stage("writing the dataset"):
        out = write_dataset(data, args.out, progress=sys.stderr.isatty())
    points = sum(len(s) for s in data.scans)
    say(
        f"{len(data)} scans ({points / len(data):.0f} points each on average) of {data.name} "
        f"written to {out} in {time.perf_counter() - start:.1f} s",
        written=out,
    )
    return 0


def _run(args) -> int:
    if wants_scans(args):  # --scans DIR: your own scans, not simulated ones (--truth etc. without it: error)
        return run_on_scans(args)
    from helpers.cli.outputs import RUN_LEGACY_MARKER, RUN_MARKER, write_run
    from helpers.config.files import given_keys, load_config
    from helpers.outdir import check_output_place
    from helpers.quality.evaluation import map_errors, run_metrics
    from helpers.quality.trust import assess
    from helpers.sim.dataset import create_dataset
    from helpers.sim.gnss import read_fixes
    from helpers.slam.flight_fit import check_grid_steps, fit_to_flight, flight_of
    from helpers.slam.pipeline import run_slam

    check_output_place(args.out, RUN_MARKER, RUN_LEGACY_MARKER)
    config = load_config(args.config)
    gnss = read_fixes(args.gnss, args.gnss_sigma, config.sensor)
    start = time.perf_counter()
    interactive = sys.stderr.isatty()
    with _stage("creating the dataset"):
        data = create_dataset(args.map, args.waypoints, config.sensor, progress=interactive)
    created = time.perf_counter() - start
    if gnss is not None:
        gnss.check_flight(len(data), args.gnss)
        sigma = ", ".join(f"{v:g}" for v in gnss.sigmas[1:])
        say(f"GNSS: {len(gnss.indices)} positions from {args.gnss}, sigma {sigma} m (horizontal, vertical)")
    flight = flight_of(data)
    if not args.reference_values:
        config, reasons = fit_to_flight(flight, config, given_keys(args.config), gnss=gnss is not None)
    check_grid_steps(flight, config)  # before a word about the fit: a refused run prints only its error
    if not args.reference_values:
        say(
            f"parameters fitted to the flight ({flight.height:.0f} m above the ground, a waypoint every "
            f"{flight.spacing:.1f} m; --reference-values keeps the reference's):",
            *(f"  {line}" for line in reasons),
        )
    with _stage("running SLAM"):
        times = data.times if data.has_times else None  # a Risley sensor's points: each deskewed by its time
        result = run_slam(data, config, progress=interactive, gnss=gnss, times=times)
    result.runtime_s = {"dataset": created, **result.runtime_s}
    with _stage("evaluating the run"):
        health = assess(result)
        m = run_metrics(data, result, map_errors(result.map_points, data.map_points), health)
    with _stage("writing the run"):
        out = write_run(result, args.out, m, data.poses[result.indices], frame=data.frame)
    report_run(m, health, out)
    return 0
