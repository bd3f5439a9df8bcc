"""Helpers for the project's tests, as numpy.testing is numpy's: ROS domains kept apart per
test and per pytest-xdist worker (``domains``), a probe node and node factories (``probe``),
process trees from /proc (``processes``), and small runs and recordings several test folders
share (``evolutions``, ``experiments``, ``recordings``).  The tests import these instead of
each other; nothing else in the package imports them."""
