"""python -m helpers, and the installed aerial-lidar-slam script: the command line (helpers.cli.main).

As the program itself, it sets what Open3D and OpenMP read when they load, unless the user has: a caller in
Python (or ``import helpers``) keeps its environment as it is."""

import os
import sys

from helpers.cli import main as cli

# OpenMP's threads (Open3D, small_gicp) otherwise spin after each parallel call and starve numpy's; lower case,
# as libgomp compares it in the user's locale. Open3D otherwise announces its web visualiser on import.
ENVIRONMENT = {"OMP_WAIT_POLICY": "passive", "OPEN3D_DISABLE_WEB_VISUALIZER": "true"}


def main(argv=None) -> int:
    """The command line; ``argv`` None means the process's own arguments: this is the program, and the
    environment is set before any command imports Open3D."""
    if argv is None:
        for name, value in ENVIRONMENT.items():
            os.environ.setdefault(name, value)
    return cli.main(argv)


if __name__ == "__main__":
    sys.exit(main())
