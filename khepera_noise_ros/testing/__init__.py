"""Helpers for the project's tests, as numpy.testing is numpy's: ROS domains kept apart per
test and per pytest-xdist worker (``domains``), a probe node and node factories (``probe``),
process trees from /proc (``processes``), small runs and recordings several test folders
share (``evolutions``, ``experiments``, ``recordings``), small recordings made by the
simulator with hidden effects (``protocols``) and the emulated robot recorded as the blind
benchmark records it (``emulated``).  The tests import these instead of each other or a
benchmark script; nothing else in the package imports them."""
