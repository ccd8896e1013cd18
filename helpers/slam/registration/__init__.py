"""Stage 3, registration: two scans put on top of each other (see :mod:`helpers.slam`)."""
