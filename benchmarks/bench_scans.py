"""Streaming a folder of scans (``run --scans``): scans per second and memory, flat over 5,000 scans.

Writes N small synthetic scans (a few hundred points each, sensor frame) into a temporary folder, opens it as
``run --scans`` does (:func:`helpers.cli.scans.open_scan_folder`), surveys it (every file read once, as the
command does before the SLAM) and then reads every scan again through the sequence the SLAM reads from.
Prints scans per second of each pass and the process's peak memory after the first tenth and at the end:
equal figures mean nothing accumulates.
Run: .venv/bin/python benchmarks/bench_scans.py [--scans 5000] [--points 400] [--format ply|npy|bin|pcd|laz] [--slam]
"""

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from helpers.cli.scans import open_scan_folder
from helpers.sim.ply import write_ply


def memory_mb() -> tuple[float, float]:
    """(resident, peak resident) memory of this process, MB (Linux /proc)."""
    fields = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    return int(fields["VmRSS"].split()[0]) / 1024, int(fields["VmHWM"].split()[0]) / 1024


def write_scan(path: Path, points: np.ndarray, fmt: str) -> None:
    if fmt == "ply":
        write_ply(path, points)
    elif fmt == "npy":
        np.save(path, points)
    elif fmt == "bin":
        np.column_stack([points, np.ones(len(points))]).astype("<f4").tofile(path)
    elif fmt == "pcd":
        n = len(points)
        head = f"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\n"
        path.write_bytes((head + "DATA binary\n").encode() + points.astype("<f4").tobytes())
    else:
        import laspy

        las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
        las.header.scales, las.header.offsets = [0.001] * 3, [0.0] * 3
        las.x, las.y, las.z = points.T
        las.gps_time = np.linspace(0.0, 0.1, len(points))
        las.write(path)


def stream(label: str, count: int, read) -> None:
    """Call ``read(i)`` for every scan, printing the rate and the memory after a tenth and at the end."""
    tenth = max(1, count // 10)
    start = time.perf_counter()
    points = 0
    for index in range(count):
        points += len(read(index))
        if index + 1 == tenth:
            rss, peak = memory_mb()
            print(f"  {label}: after {tenth} scans: {rss:.0f} MB resident, peak {peak:.0f} MB")
    seconds = time.perf_counter() - start
    rss, peak = memory_mb()
    print(f"  {label}: after {count} scans: {rss:.0f} MB resident, peak {peak:.0f} MB")
    print(f"  {label}: {count / seconds:,.0f} scans/s ({points / seconds / 1e6:.1f} M points/s, {seconds:.1f} s)")


def slam_pass(root: Path) -> None:
    """``run --scans`` on the shipped default flight written as a folder (689 scans): scans per second of the
    whole command (reading, SLAM, metrics, writing) and the peak memory."""
    import argparse as ap

    import helpers
    from helpers.cli.outputs import write_dataset
    from helpers.cli.own_scans import run_on_scans

    write_dataset(helpers.create_dataset(), root / "D")
    rss, peak = memory_mb()
    print(f"run --scans on the default flight: before, {rss:.0f} MB resident, peak {peak:.0f} MB")
    names = ("map", "waypoints", "config", "gnss", "gnss_sigma", "sensor_height", "scan_spacing")
    args = ap.Namespace(**dict.fromkeys(names), scans=str(root / "D" / "scans"), out=str(root / "R"))
    args.truth = str(root / "D" / "poses_gt.txt")
    start = time.perf_counter()
    run_on_scans(args)
    seconds = time.perf_counter() - start
    rss, peak = memory_mb()
    count = len(list((root / "D" / "scans").iterdir()))
    print(f"run --scans: {count} scans in {seconds:.0f} s = {count / seconds:.1f} scans/s end to end")
    print(f"run --scans: after, {rss:.0f} MB resident, peak {peak:.0f} MB")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=5000)
    parser.add_argument("--points", type=int, default=400)
    parser.add_argument("--format", choices=("ply", "npy", "bin", "pcd", "laz"), default="ply")
    parser.add_argument("--slam", action="store_true", help="then run --scans on the default flight (689 scans)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    root = Path(tempfile.mkdtemp(prefix="bench_scans_"))
    try:
        start = time.perf_counter()
        for k in range(args.scans):
            n = args.points
            points = np.column_stack([rng.uniform(-25, 25, (n, 2)), -600.0 + rng.normal(0, 0.2, n)])
            write_scan(root / f"{k:06d}.{args.format}", points, args.format)
        print(f"wrote {args.scans} {args.format} scans of {args.points} points in {time.perf_counter() - start:.1f} s")
        rss, peak = memory_mb()
        print(f"before reading: {rss:.0f} MB resident, peak {peak:.0f} MB")
        folder = open_scan_folder(root)
        start = time.perf_counter()
        folder.survey()
        seconds = time.perf_counter() - start
        print(f"survey (each file read once): {len(folder.files) / seconds:,.0f} scans/s, {len(folder)} kept")
        stream("streamed through folder[i]", len(folder), folder.__getitem__)
        if args.slam:
            slam_pass(root)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
