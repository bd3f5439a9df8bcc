"""The outside blind generator: effects drawn in shapes the diagnosis was not written for.

Written without the project's effect code (reality/effects.py, gap/) or the
first blind benchmark; it knows only the public recording format, the effect
vocabulary's names and the ``khepera-noise`` command line.
"""
