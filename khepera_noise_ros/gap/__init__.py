"""Sim-to-real gap diagnosis: where the simulator and a recording differ, which unmodelled
effect explains it, and how far adding that effect shrinks the gap on held-out data.

  statistics  block sums of a recording and every compared statistic, bootstrapped
  closedloop  the closed-loop statistics (fitness factors, turn responses)
  turnscatter the turn's scatter: what a zero-mean random turn error changes
  blocklength the one block-length rule of the project's block bootstraps
  allan       Allan deviation of the residuals: fast against slow, per sensor and shared
  where       real against simulated statistics: z, Holm, discrepancy, localisation
  replay      a recording's protocol reproduced in the simulator
  simulate    the simulator with effects (EffectEpisodes; also the simulator node's hook)
  effects     simulator-side models of the vocabulary's effects, as a JSON parameter
  target      real recordings held against the simulator, for fitting and scoring
  fit         locating and fitting each effect
  fitturn     fitting the turn error: scale, random slip, creep
  fitbase     what the fitters share (Candidate, detection threshold, golden search)
  spreadlaw   laws of the noise's spread against the level
  dropout     isolated readings at a sensor's extremes: marked, repaired, their statistics
  limits      dropouts counted against the simulator, for the fit
  rarecount   dropout shares judged by an exact count test against many simulated copies
  compound    forward selection of a set of effects, each fitted jointly
  remainder   what the named effects leave, and its empirical model
  groups      dependence groups by clustering correlations
  split       fit and held-out parts (by episode or by condition)
  diagnose    the three questions, and the verdict
  transfer    the transfer experiment with and without the fitted effect
  noisefit    the paper's combination model fitted to a stationary recording
  report      diagnosis.json, report.md with figures, fitted_params.yaml
  simconfig   the simulator's params YAML, read and written
"""
