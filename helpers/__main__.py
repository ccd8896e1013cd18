"""Command line: ``python -m helpers dataset|run|site ...`` (installed: ``aerial-lidar-slam``).

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

from .errors import SlamError


class Terminated(KeyboardInterrupt):
    """SIGTERM (a ``kill``, a job scheduler, a container stopping) raised as
    Ctrl-C is, so that what the command began is removed on the way out."""


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
    parser = argparse.ArgumentParser(prog="python -m helpers", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log what each stage does")
    sub = parser.add_subparsers(dest="command", required=True)

    ds = sub.add_parser("dataset", help="simulate the lidar scans of a flight over a map")
    _map_arguments(ds)
    ds.add_argument("--out", required=True, help="output folder (scans/, poses_gt.txt, map_gt.ply)")

    run = sub.add_parser("run", help="create the dataset and run the whole SLAM pipeline on it")
    _map_arguments(run)
    run.add_argument("--out", required=True, help="output folder (metrics.json, trajectories, map.ply)")
    run.add_argument(
        "--reference-values",
        action="store_true",
        help="keep the configured values (by default the geometry-dependent ones the config file does not set "
        "are fitted to the flight's height and waypoint spacing: helpers.fitting)",
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

    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    try:
        if args.command == "dataset":
            return _dataset(args)
        if args.command == "run":
            return _run(args)
        if args.command == "site":
            from .site import build_site

            index = build_site(args.out, execute=not args.no_execute)
            print(f"book written: {index}")
            return 0
    except SlamError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # the last line of defence: the stages turn the ones they expect into SlamError
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"error: {'terminated' if isinstance(exc, Terminated) else 'interrupted'}", file=sys.stderr)
        return 128 + (signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT)
    return 1


def _map_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", help=".las, .laz or .tar.gz holding one (default: the embedded scene)")
    parser.add_argument("--waypoints", help=".mat with gTruthTraj or .csv of x,y[,z] (default: a loop)")
    parser.add_argument("--config", help="TOML file with a table per stage: [sensor], [features], [registration], ...")


def _dataset(args) -> int:
    from .configfile import load_config
    from .dataset import LEGACY_MARKER, MARKER, create_dataset, write_dataset
    from .outdir import check_output_place

    check_output_place(args.out, MARKER, LEGACY_MARKER)
    config = load_config(args.config)
    start = time.perf_counter()
    data = create_dataset(args.map, args.waypoints, config.sensor, progress=sys.stderr.isatty())
    out = write_dataset(data, args.out, progress=sys.stderr.isatty())
    points = sum(len(s) for s in data.scans)
    print(
        f"{len(data)} scans ({points / len(data):.0f} points each on average) of {data.name} "
        f"written to {out} in {time.perf_counter() - start:.1f} s"
    )
    return 0


def _run(args) -> int:
    from .configfile import given_keys, load_config
    from .dataset import create_dataset
    from .evaluation import map_errors, run_metrics
    from .fitting import check_grid_steps, fit_to_flight, flight_of
    from .health import assess
    from .outdir import check_output_place
    from .output import LEGACY_MARKER, MARKER, write_run
    from .pipeline import run_slam

    check_output_place(args.out, MARKER, LEGACY_MARKER)
    config = load_config(args.config)
    gnss = _gnss(args, config)
    start = time.perf_counter()
    interactive = sys.stderr.isatty()
    data = create_dataset(args.map, args.waypoints, config.sensor, progress=interactive)
    created = time.perf_counter() - start
    if gnss is not None:
        gnss.check_flight(len(data), args.gnss)
        sigma = ", ".join(f"{v:g}" for v in gnss.sigmas[1:])
        print(f"GNSS: {len(gnss.indices)} positions from {args.gnss}, sigma {sigma} m (horizontal, vertical)")
    flight = flight_of(data)
    if not args.reference_values:
        config, reasons = fit_to_flight(flight, config, given_keys(args.config), gnss=gnss is not None)
    check_grid_steps(flight, config)  # before a word about the fit: a refused run prints only its error
    if not args.reference_values:
        print(
            f"parameters fitted to the flight ({flight.height:.0f} m above the ground, a waypoint every "
            f"{flight.spacing:.1f} m; --reference-values keeps the reference's):"
        )
        print("\n".join(f"  {line}" for line in reasons))
    result = run_slam(data, config, progress=interactive, gnss=gnss)
    result.runtime_s = {"dataset": created, **result.runtime_s}
    health = assess(result)
    m = run_metrics(data, result, map_errors(result.map_points, data.map_points), health)
    out = write_run(result, args.out, m, data.poses[result.indices])
    print(
        f"{m['n_accepted']} accepted scans of {m['n_scans']}, {m['n_loop_closures']} loop closures "
        f"({m['n_false_loop_closures']} false); ATE {m['ate_rmse_odometry_m']:.2f} m (odometry) -> "
        f"{m['ate_rmse_optimized_m']:.2f} m (optimised); {m['runtime_s']['total']:.0f} s; written to {out}"
    )
    print(health.summary())
    if not health.trusted:
        print(f'warning: {health.warning()} (metrics.json: "trusted": false)', file=sys.stderr)
    return 0


def _gnss(args, config):
    """The GNSS fixes ``--gnss`` names, each with the sigma of ``--gnss-sigma`` or else of ``[sensor]``."""
    if args.gnss is None:
        if args.gnss_sigma is not None:
            raise SlamError("--gnss-sigma needs --gnss FILE (the positions it is the sigma of)")
        return None
    from .gnss import parse_sigma, read_gnss

    if args.gnss_sigma is not None:
        sigmas = parse_sigma(args.gnss_sigma)
    elif config.sensor.gnss:
        horizontal, vertical = config.sensor.gnss_sigma_horizontal, config.sensor.gnss_sigma_vertical
        sigmas = [horizontal, horizontal, vertical]
    else:
        raise SlamError("--gnss needs the positions' sigma: --gnss-sigma H[,V] (m) or [sensor] gnss sigmas")
    return read_gnss(args.gnss, sigmas)


if __name__ == "__main__":
    sys.exit(main())
