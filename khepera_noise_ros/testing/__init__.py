"""Helpers for the project's tests, as numpy.testing is numpy's: small recordings made by
the simulator with hidden effects (``protocols``) and the emulated robot recorded as the
blind benchmark records it (``emulated``), for the diagnosis's tests.  The tests import
these instead of each other or a benchmark script; nothing else in the package imports
them."""
