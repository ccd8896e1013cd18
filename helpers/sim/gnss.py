"""GNSS positions: simulated per scan, written beside a dataset, read back
for ``python -m helpers run --gnss FILE`` and added to the pose graph as
position fixes (GTSAM's GPS factor, :class:`helpers.slam.graph.factors.PositionFactor`).

A position is the sensor's, in the map frame of the run: the frame of the
dataset's ``poses_gt.txt`` (a tile centred on its XY mid-point, metres).
Each row names the scan it belongs to by its index in the flight (0, 1,
2, ...); fixes of scans that are not pose-graph nodes (skipped by
``skip_frames``) are not used.

Two formats are read, chosen by the file's suffix:

* ``.csv``: ``index,x,y,z`` per line, with or without a header line (a first
  line that holds no number), as the simulator writes ``gnss.csv``;
* ``.txt`` or ``.tum``: TUM, ``t x y z qx qy qz qw`` per line, ``t`` the scan
  index (the quaternion is not used), ``#`` comment lines allowed.

The sigma of a fix is not in the file: ``run --gnss-sigma H[,V]`` gives it,
else the ``[sensor]`` GNSS sigmas that simulated it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from helpers.config.bounds import MAX_SCANS, human_size
from helpers.errors import SlamError
from helpers.paths import input_file

FILE_NAME = "gnss.csv"  # what the simulator writes beside poses_gt.txt
HEADER = "index,x,y,z"
MAX_BYTES = 200 * MAX_SCANS  # a TUM line is under 200 bytes: a larger file holds more fixes than a flight has scans
GNSS_STREAM = 71  # the GNSS noise's own random stream, apart from the scans' (seeded by (seed, scan index))


@dataclass(frozen=True)
class GnssFixes:
    """Position fixes: ``indices`` (M,) scan indices, ``positions`` (M, 3) map frame, ``sigmas`` (3,) x y z, m."""

    indices: np.ndarray
    positions: np.ndarray
    sigmas: np.ndarray

    def __post_init__(self):
        sigmas = np.asarray(self.sigmas, dtype=float)
        if sigmas.shape != (3,) or not (np.all(np.isfinite(sigmas)) and np.all(sigmas > 0)):
            raise SlamError(f"GNSS sigmas must be 3 positive numbers of metres (x y z), got {self.sigmas}")
        positions = np.asarray(self.positions, dtype=float)
        if positions.shape != (len(self.indices), 3) or not np.all(np.isfinite(positions)):
            raise SlamError(f"GNSS positions must be {len(self.indices)} x 3 finite numbers, one row per index")

    def check_flight(self, n_scans: int, source: str = "the GNSS file") -> None:
        """Refuse fixes of scans the flight does not have."""
        outside = self.indices[(self.indices < 0) | (self.indices >= n_scans)]
        if outside.size:
            raise SlamError(
                f"{source}: {outside.size} scan index(es) not in the flight of {n_scans} scans "
                f"(0 to {n_scans - 1}), e.g. {int(outside[0])}"
            )


def simulate_gnss(positions: np.ndarray, horizontal: float, vertical: float, seed: int) -> np.ndarray:
    """(N, 3) noisy copies of the true ``positions``: Gaussian errors of sigma
    ``horizontal`` on x and y and ``vertical`` on z (m), drawn from a generator
    seeded with ``(seed, GNSS_STREAM)`` (the same flight and seed, the same fixes)."""
    rng = np.random.default_rng([seed, GNSS_STREAM])
    noise = rng.standard_normal((len(positions), 3)) * [horizontal, horizontal, vertical]
    return np.asarray(positions, dtype=float) + noise


def write_gnss(path: str | Path, positions: np.ndarray) -> None:
    """``index,x,y,z`` per scan, with a header line (:func:`read_gnss` reads it back)."""
    rows = np.column_stack([np.arange(len(positions)), positions])
    np.savetxt(path, rows, fmt=["%d", "%.4f", "%.4f", "%.4f"], delimiter=",", header=HEADER, comments="")


def parse_sigma(text: str) -> np.ndarray:
    """``"H"`` or ``"H,V"`` (m) -> (3,) sigmas x y z; both must be positive numbers."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (1, 2) or not all(np.isfinite(v) and v > 0 for v in values):
        raise SlamError(f"--gnss-sigma must be one or two positive numbers of metres (H or H,V), got {text!r}")
    horizontal, vertical = values[0], values[-1]
    return np.array([horizontal, horizontal, vertical])


def read_gnss(path: str | Path, sigmas) -> GnssFixes:
    """The fixes of a ``.csv`` (``index,x,y,z``) or TUM (``.txt``, ``.tum``) file, each with ``sigmas``
    (3,); any line that is not such numbers is an error naming it, and no fix is dropped."""
    path = input_file(path, "GNSS file")
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".txt", ".tum"):
        raise SlamError(f"GNSS positions must be a .csv (index,x,y,z) or TUM (.txt, .tum) file, got {path.name}")
    size = path.stat().st_size
    if size > MAX_BYTES:
        raise SlamError(f"{path.name} is {human_size(size)}, more fixes than a flight has scans")
    csv = suffix == ".csv"
    expected, layout = (4, HEADER) if csv else (8, "t x y z qx qy qz qw")
    text = path.read_text(encoding="utf-8-sig", errors="replace")
    lines = [(n, line.strip()) for n, line in enumerate(text.splitlines(), 1) if line.strip()]
    lines = [(n, line) for n, line in lines if not line.startswith("#")]
    if lines and not any(_is_number(cell) for cell in _cells(lines[0][1], csv)):
        lines = lines[1:]  # a header such as "index,x,y,z"
    if not lines:
        raise SlamError(f"{path.name} holds no GNSS positions")
    rows = np.empty((len(lines), expected))
    for r, (number, line) in enumerate(lines):
        cells = _cells(line, csv)
        if len(cells) != expected or not all(_is_number(c) for c in cells):
            raise SlamError(
                f"{path.name} line {number}: every line must be {layout} ({expected} numbers), got {line[:50]!r}"
            )
        rows[r] = [float(c) for c in cells]
        if not np.all(np.isfinite(rows[r])):
            raise SlamError(f"{path.name} line {number}: positions must be finite numbers, got {line[:50]!r}")
        if rows[r, 0] != round(rows[r, 0]) or abs(rows[r, 0]) > MAX_SCANS:
            raise SlamError(f"{path.name} line {number}: the first column must be a scan index, got {cells[0]!r}")
    indices = rows[:, 0].astype(np.int64)
    unique, counts = np.unique(indices, return_counts=True)
    if np.any(counts > 1):
        raise SlamError(f"{path.name}: scan {int(unique[counts > 1][0])} has more than one position")
    return GnssFixes(indices, rows[:, 1:4].copy(), np.asarray(sigmas, dtype=float))


def _cells(line: str, csv: bool) -> list[str]:
    return [c.strip() for c in line.split(",")] if csv else line.split()


def _is_number(text: str) -> bool:
    """A number as the project's CSV readers take one ("1_000", which Python alone reads, is not)."""
    if "_" in text:
        return False
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_fixes(path, sigma_text: str | None, sensor) -> GnssFixes | None:
    """The fixes of GNSS file ``path`` (None: none), each with the sigma ``sigma_text`` gives ("H[,V]" m) or
    else the ``sensor``'s (a :class:`helpers.config.SensorConfig`) GNSS sigmas, as the command line takes them."""
    if path is None:
        if sigma_text is not None:
            raise SlamError("--gnss-sigma needs --gnss FILE (the positions it is the sigma of)")
        return None
    if sigma_text is not None:
        sigmas = parse_sigma(sigma_text)
    elif sensor.gnss:
        sigmas = [sensor.gnss_sigma_horizontal, sensor.gnss_sigma_horizontal, sensor.gnss_sigma_vertical]
    else:
        raise SlamError("--gnss needs the positions' sigma: --gnss-sigma H[,V] (m) or [sensor] gnss sigmas")
    return read_gnss(path, sigmas)
