"""Sim-to-real gap diagnosis: where the simulator and a recording differ, which unmodelled
effect explains it, and how far adding that effect shrinks the gap on held-out data.

  statistics  block sums of a recording and every compared statistic, bootstrapped
  where       real against simulated statistics: z, Holm, discrepancy, localisation
  replay      a recording's protocol reproduced in the simulator
  simulate    the simulator with effects (EffectEpisodes; also the simulator node's hook)
  effects     simulator-side models of the vocabulary's effects, as a JSON parameter
  target      real recordings held against the simulator, for fitting and scoring
  fit         locating and fitting each effect
  groups      dependence groups by clustering correlations
  split       fit and held-out parts (by episode or by condition)
  diagnose    the three questions, and the verdict
  transfer    the transfer experiment with and without the fitted effect
  noisefit    the paper's combination model fitted to a stationary recording
  report      diagnosis.json, report.md with figures, fitted_params.yaml
  simconfig   the simulator's params YAML, read and written
"""
