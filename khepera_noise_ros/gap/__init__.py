"""Sim-to-real gap diagnosis: where the simulator and a recording differ, which effect of
``effects.REGISTRY`` explains it, and how far adding it shrinks the gap on held-out data.

  diagnose    the three questions and the verdict      select      the compound
  target      recordings against the simulator         evidence    what locates an effect
  compare     z, Holm, discrepancy, where              families    the statistic families
  stationary  statistics of stationary recordings      closedloop  ... of closed-loop ones
  converter   limits, the lattice                      dropouts    lost readings, counted
  bootstrap   the block bootstrap                      replay      a protocol in the simulator
  protocol    what a recording is                      split       fit and held-out parts
  allan       Allan deviation                          turns       turns: per command, measured
"""
