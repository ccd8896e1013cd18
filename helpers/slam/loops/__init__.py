"""Stage 5, loop closure: where to search, which submap and scan match, place recognition (see :mod:`helpers.slam`)."""
