"""The one exception type of the package.

Every check on user input raises :class:`SlamError` with a sentence a person
can act on; the command line prints that sentence on one line and exits 2.
"""


class SlamError(Exception):
    """Bad input or a stage that cannot go on, explained in plain words."""
