"""Do the tests bite? Break one step of the pipeline on purpose and check that the suite fails.

Each mutant is a one-line change to a copy of the repository (the working
tree is never touched). The whole suite, unit tests and notebooks alike,
runs on the copy with ``pytest -x`` and must end with failed tests (exit
code 1): a mutant that passes, or a run that fails for another reason (a
collection or usage error), is reported and this script exits non-zero. The
test file expected to catch a mutant runs first, on its own, so a caught
mutant costs a minute rather than the whole suite; if it passes, the whole
suite runs.

    python tests/mutants.py            # every mutant
    python tests/mutants.py identity   # the ones whose name contains "identity"
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

# name: (test file run first, file mutated, the line as it is, the line as the mutant has it)
MUTANTS = {
    "robust fit returns the identity": (
        "tests/test_registration.py",
        "helpers/slam/registration/msac.py",
        "    return _uncentre(best, moving_centre, fixed_centre), best_inliers\n",
        "    return np.eye(4), best_inliers\n",
    ),
    "the yaw fit returns the identity": (
        "tests/test_fit4dof.py",
        "helpers/slam/registration/msac_yaw.py",
        "    return YawFit(T, best_inliers, float(best_cost), drawn)\n",
        "    return YawFit(np.eye(4), best_inliers, float(best_cost), drawn)\n",
    ),
    "loop closure disabled": (
        "tests/test_pipeline.py",
        "helpers/slam/loops/closer.py",
        "        if len(self.submaps) <= self.settings.sub_map_thresh:\n",
        "        if True:\n",
    ),
    "the odometry never sees a step that measured nothing": (
        "tests/test_odometry.py",
        "helpers/slam/odometry.py",
        "            self.blind.append(motion is not None and pair.blind(motion))\n",
        "            self.blind.append(False)\n",
    ),
    "the matcher's gate reaches only its own cell": (
        "tests/test_matching.py",
        "helpers/slam/registration/matching.py",
        "        around = [by_cell.get((cx + dx, cy + dy)) for dx in (-1, 0, 1) for dy in (-1, 0, 1)]\n",
        "        around = [by_cell.get((cx, cy))]\n",
    ),
    "a step the gate misleads is not matched again": (
        "tests/test_odometry.py",
        "helpers/slam/registration/pair.py",
        "    if near is not None and pair.fallback is not None:\n",
        "    if False:\n",
    ),
    "the graph's expected ATE leaves the GNSS fixes out": (
        "tests/test_health.py",
        "helpers/quality/graph_checks.py",
        "    for fix in result.gnss_factors:\n",
        "    for fix in []:\n",
    ),
    "the graph answers the drift rules without testing whether it bent to a loop": (
        "tests/test_health.py",
        "helpers/quality/trust.py",
        "    if bent_pull > CORRECTION_FLOOR_M:\n",
        "    if False:\n",
    ),
    "the loop search starts ICP from the odometry pose": (
        "tests/test_uncertainty.py",
        "helpers/slam/loops/search.py",
        "    starts = [scan_pose if starts is None else starts[k] for k in tried]\n",
        "    starts = [scan_pose for k in tried]\n",
    ),
    "a run with GNSS keeps the fixed sigmas": (
        "tests/test_gnss.py",
        "helpers/slam/flight_fit.py",
        "    elif gnss:\n",
        "    elif False:\n",
    ),
    "the loop search ignores the GNSS fixes": (
        "tests/test_uncertainty.py",
        "helpers/slam/loops/closer.py",
        "            self.uncertainty.add_fix(node, *fix)\n",
        "            pass\n",
    ),
    "the loop search never recognises a place": (
        "tests/test_places.py",
        "helpers/slam/loops/closer.py",
        "        elif self.places is not None and self.places.lost and not candidates.closed:\n",
        "        elif False:\n",
    ),
    "a loop's pin test ignores how much of the scan paired": (
        "tests/test_loopclosure.py",
        "helpers/slam/registration/icp_service.py",
        "        return overlap * constraint\n",
        "        return constraint\n",
    ),
    "a loop's best match is registered again on the whole scan": (
        "tests/test_loopclosure.py",
        "helpers/slam/registration/overlap.py",
        "        keep = inside(outline, transform_points(moving, T), 0.0)\n",
        "        keep = np.ones(len(moving), dtype=bool)\n",
    ),
    "ICP returns its initial guess": (
        "tests/test_registration.py",
        "helpers/slam/registration/icp.py",
        "    transform = np.array(result.T_target_source)\n",  # small_gicp, the default back end
        "    transform = init.copy()\n",
    ),
}


def mutated_copy(root: Path, file: str, line: str, mutant: str) -> Path:
    """The tracked files of the repository copied under ``root``, with one line changed."""
    copy = root / "repo"
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    for name in tracked.decode().split("\0"):
        if name and (REPO / name).is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, copy / name)
    (root / "shared").symlink_to(REPO.parent / "shared")  # the real tile stays beside the repository
    source = (copy / file).read_text()
    if source.count(line) != 1:
        raise SystemExit(f"error: the line to mutate in {file} was found {source.count(line)} times, not once")
    (copy / file).write_text(source.replace(line, mutant))
    return copy


def suite_fails(copy: Path, first: str) -> tuple[bool, str]:
    """Run ``first`` on ``copy``, then, if it passed, the whole suite, until the
    first failure: (failed as a test should, the last lines of the run)."""
    env = {**os.environ, "PYTHONPATH": str(copy), "HELPERS_CACHE": str(copy / "data" / "cache")}
    for targets in ([first], []):
        command = [sys.executable, "-m", "pytest", "-x", "-q", *targets]
        done = subprocess.run(command, cwd=copy, env=env, capture_output=True, text=True)
        if done.returncode != 0:
            break
    tail = "\n".join(done.stdout.strip().splitlines()[-3:])
    return done.returncode == 1, tail


def main(argv: list[str]) -> int:
    chosen = {name: m for name, m in MUTANTS.items() if not argv or any(a in name for a in argv)}
    survivors = []
    for name, (first, file, line, mutant) in chosen.items():
        with tempfile.TemporaryDirectory(prefix="mutant-") as root:
            failed, tail = suite_fails(mutated_copy(Path(root), file, line, mutant), first)
        indented = tail.replace("\n", "\n    ")
        print(f"{'caught' if failed else 'SURVIVED'}: {name}\n    {indented}", flush=True)
        if not failed:
            survivors.append(name)
    print(f"{len(chosen) - len(survivors)} of {len(chosen)} mutants caught")
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
