"""Command line: ``python -m helpers dataset|run|flight|site ...`` (installed: ``aerial-lidar-slam``).

Errors in the input end in one line on stderr and exit code 2, never a
traceback, and never a half-written output folder. The output folder is
checked before any work starts (:func:`helpers.outdir.check_output_place`).
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import resource
import signal
import sys
import threading
import time
from contextlib import contextmanager

from helpers.cli import flight
from helpers.errors import SlamError


class Terminated(KeyboardInterrupt):
    """SIGTERM (a ``kill``, a job scheduler, a container stopping) raised as
    Ctrl-C is, so that what the command began is removed on the way out."""


class StreamError(Exception):
    """Standard output could not take the report (full, or closed) of a command whose outputs are written."""


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
            _say(f"book written: {index}")
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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m helpers", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log what each stage does")
    sub = parser.add_subparsers(dest="command", required=True)

    ds = sub.add_parser("dataset", help="simulate the lidar scans of a flight over a map")
    _map_arguments(ds)
    ds.add_argument("--out", required=True, help="output folder (scans/, poses_gt.txt, map_gt.ply)")

    flight.add_parser(sub)

    run = sub.add_parser("run", help="create the dataset and run the whole SLAM pipeline on it")
    _map_arguments(run)
    run.add_argument("--out", required=True, help="output folder (metrics.json, trajectories, map.ply)")
    run.add_argument(
        "--reference-values",
        action="store_true",
        help="keep the configured values (by default the geometry-dependent ones the config file does not set "
        "are fitted to the flight's height and waypoint spacing: helpers.slam.flight_fit)",
    )
    run.add_argument(
        "--gnss",
        metavar="FILE",
        help="GNSS positions per scan, map frame (.csv index,x,y,z or TUM .txt/.tum, t = scan index), added to "
        "the pose graph as GPS factors",
    )
    run.add_argument(
        "--gnss-sigma",
        metavar="H[,V]",
        help="sigma of a GNSS position, metres, horizontal[,vertical] (default: the [sensor] gnss sigmas)",
    )

    site = sub.add_parser("site", help="execute the notebooks and build them into a book that opens from disk")
    site.add_argument("--out", default="build/html", help="output folder (default: build/html)")
    site.add_argument("--no-execute", action="store_true", help="export the notebooks as committed")
    return parser


def _map_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", help=".las, .laz or .tar.gz holding one (default: the embedded scene)")
    parser.add_argument("--waypoints", help=".mat with gTruthTraj or .csv of x,y[,z] (default: a loop)")
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
    _say(
        f"{len(data)} scans ({points / len(data):.0f} points each on average) of {data.name} "
        f"written to {out} in {time.perf_counter() - start:.1f} s",
        written=out,
    )
    return 0


def _run(args) -> int:
    from helpers.cli.outputs import RUN_LEGACY_MARKER, RUN_MARKER, write_run
    from helpers.config.files import given_keys, load_config
    from helpers.outdir import check_output_place
    from helpers.quality.evaluation import map_errors, run_metrics
    from helpers.quality.trust import assess
    from helpers.sim.dataset import create_dataset
    from helpers.slam.flight_fit import check_grid_steps, fit_to_flight, flight_of
    from helpers.slam.pipeline import run_slam

    check_output_place(args.out, RUN_MARKER, RUN_LEGACY_MARKER)
    config = load_config(args.config)
    gnss = _gnss(args, config)
    start = time.perf_counter()
    interactive = sys.stderr.isatty()
    with _stage("creating the dataset"):
        data = create_dataset(args.map, args.waypoints, config.sensor, progress=interactive)
    created = time.perf_counter() - start
    if gnss is not None:
        gnss.check_flight(len(data), args.gnss)
        sigma = ", ".join(f"{v:g}" for v in gnss.sigmas[1:])
        _say(f"GNSS: {len(gnss.indices)} positions from {args.gnss}, sigma {sigma} m (horizontal, vertical)")
    flight = flight_of(data)
    if not args.reference_values:
        config, reasons = fit_to_flight(flight, config, given_keys(args.config), gnss=gnss is not None)
    check_grid_steps(flight, config)  # before a word about the fit: a refused run prints only its error
    if not args.reference_values:
        _say(
            f"parameters fitted to the flight ({flight.height:.0f} m above the ground, a waypoint every "
            f"{flight.spacing:.1f} m; --reference-values keeps the reference's):",
            *(f"  {line}" for line in reasons),
        )
    with _stage("running SLAM"):
        result = run_slam(data, config, progress=interactive, gnss=gnss)
    result.runtime_s = {"dataset": created, **result.runtime_s}
    with _stage("evaluating the run"):
        health = assess(result)
        m = run_metrics(data, result, map_errors(result.map_points, data.map_points), health)
    with _stage("writing the run"):
        out = write_run(result, args.out, m, data.poses[result.indices])
    if not health.trusted:  # first: a report that cannot be printed must not take the warning with it
        print(f'warning: {health.warning()} (metrics.json: "trusted": false)', file=sys.stderr)
    _say(
        f"{m['n_accepted']} accepted scans of {m['n_scans']}, {m['n_loop_closures']} loop closures "
        f"({m['n_false_loop_closures']} false); ATE {m['ate_rmse_odometry_m']:.2f} m (odometry) -> "
        f"{m['ate_rmse_optimized_m']:.2f} m (optimised); {m['runtime_s']['total']:.0f} s; written to {out}",
        health.summary(),
        written=out,
    )
    return 0


def _say(*lines: str, written=None) -> None:
    """Print ``lines`` on standard output now; a :class:`StreamError` if it cannot take them (full, closed),
    saying whether the command's outputs (``written``) are already whole."""
    try:
        print("\n".join(lines), flush=True)
    except OSError as exc:
        if sys.stdout is sys.__stdout__:  # what stays in its buffer goes nowhere at exit, instead of a traceback
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        if written is None:
            raise SlamError(f"cannot write to standard output: {exc.strerror or exc}") from None
        raise StreamError(f"{exc.strerror or exc}; {written} was written in full") from None


@contextmanager
def _stage(step: str):
    """Out of memory within ``step`` (Python's or numpy's MemoryError, a library's "out of memory") as one
    :class:`SlamError` naming the step, what it asked for when known, and the memory in use and allowed."""
    try:
        yield
    except (MemoryError, RuntimeError) as exc:
        text = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", str(exc))  # Open3D colours its messages
        if isinstance(exc, RuntimeError) and not re.search(r"out of memory|bad_alloc|cannot allocate", text, re.I):
            raise
        from helpers.config.bounds import human_size

        asked = getattr(exc, "_total_size", None)  # numpy's _ArrayMemoryError knows it
        asked = f"{human_size(asked)} more" if asked else "more memory"
        in_use = human_size(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)  # Linux: kB
        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        allowed = "" if limit == resource.RLIM_INFINITY else f" under a limit of {human_size(limit)} (ulimit -v)"
        raise SlamError(
            f"out of memory while {step}: it asked for {asked} with up to {in_use} in use{allowed}; "
            "free memory, raise the limit, or give a smaller map or flight"
        ) from None


def _gnss(args, config):
    """The GNSS fixes ``--gnss`` names, each with the sigma of ``--gnss-sigma`` or else of ``[sensor]``."""
    if args.gnss is None:
        if args.gnss_sigma is not None:
            raise SlamError("--gnss-sigma needs --gnss FILE (the positions it is the sigma of)")
        return None
    from helpers.sim.gnss import parse_sigma, read_gnss

    if args.gnss_sigma is not None:
        sigmas = parse_sigma(args.gnss_sigma)
    elif config.sensor.gnss:
        horizontal, vertical = config.sensor.gnss_sigma_horizontal, config.sensor.gnss_sigma_vertical
        sigmas = [horizontal, horizontal, vertical]
    else:
        raise SlamError("--gnss needs the positions' sigma: --gnss-sigma H[,V] (m) or [sensor] gnss sigmas")
    return read_gnss(args.gnss, sigmas)
