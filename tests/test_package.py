"""The package as a user meets it: importing it changes nothing around it."""

import subprocess
import sys

CHECK = """
import os, sys
before = dict(os.environ)
import helpers, helpers.viz, helpers.site
assert dict(os.environ) == before, sorted(set(os.environ.items()) ^ set(before.items()))
heavy = [name for name in ("pyvista", "vtk", "trame", "matplotlib.pyplot") if name in sys.modules]
assert not heavy, heavy
"""


def test_importing_the_package_sets_no_variable_and_draws_nothing():
    done = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
