"""``python -m helpers``: the command line (:mod:`helpers.cli.main`)."""

import sys

from helpers.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
