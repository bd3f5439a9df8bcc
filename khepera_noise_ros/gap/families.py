"""The registry of statistic families: each family's part, floor and use, declared once;
a family missing from it is an error, not a default."""
from __future__ import annotations

import functools
from dataclasses import dataclass

PARTS = ('stationary', 'closed_loop', 'closed_loop_noise', 'dropout', 'loop_values')
FLOOR = 0.002


@dataclass(frozen=True)
class Family:
    name: str
    part: str                  # one of PARTS
    floor: float = FLOOR       # the least standard error (a count, a lattice of readings)
    limits: bool = False       # only a limit (or a dropout) is fitted to it
    lattice: bool = False      # the rounding choice reads it (the value lattice)
    widened: bool = False      # a drift's wander widens its error bars (``select``)
    counted: bool = False      # a rare count, judged by a count test (``converter``)


def _family(part: str, names: str, **facts: object) -> list[Family]:
    return [Family(n, part, **facts) for n in names.split()]  # type: ignore[arg-type]


# Readings are integers: a level is not known better than a uniform error of +-0.5 (sd
# 0.29); where a pile is looked for is fixed in the bootstrap, so its error is floored;
# a dropout share is a count floored at 1 in 10,000; headings are in tenths of a degree.
FAMILIES: dict[str, Family] = {f.name: f for f in (
    _family('stationary', 'level', floor=0.3, widened=True)
    + _family('stationary', 'spread', floor=0.05, widened=True)
    + _family('stationary', 'correlation autocorrelation own_autocorrelation kurtosis '
                            'spread_vs_level step_response')
    + _family('stationary', 'mode_share granularity', lattice=True)
    + _family('stationary', 'pileup', floor=0.004, limits=True, lattice=True)
    + _family('dropout', 'dropout closed_loop_dropout', floor=1e-4, limits=True, counted=True)
    + _family('loop_values', 'loop_granularity')
    + _family('closed_loop', 'closed_loop_level', floor=0.3)
    + _family('closed_loop', 'fitness_balance fitness_intensity fitness_turning turn_power '
                             'turn_right_fraction turn_response sensor_turn_response '
                             'turn_size turn_scatter')
    + _family('closed_loop', 'turn_size_scatter', floor=0.03)
    + _family('closed_loop', 'turn_imbalance', floor=0.3)
    + _family('closed_loop', 'turn_by_command turn_by_command_scatter', floor=0.05)
    + _family('closed_loop', 'turn_step_response')
    + _family('closed_loop_noise', ' '.join(f'loop_{view}_{what}'
                                            for view in ('still', 'residual', 'change')
                                            for what in ('spread', 'correlation',
                                                         'autocorrelation'))))}


def of_part(part: str) -> frozenset[str]:
    """The families that count in ``part``."""
    if part not in PARTS:
        raise KeyError(f'no part {part!r}; parts are {PARTS}')
    return frozenset(n for n, f in FAMILIES.items() if f.part == part)


@functools.cache
def having(fact: str) -> frozenset[str]:
    """The families for which ``fact`` (limits, lattice, widened, counted) holds."""
    return frozenset(n for n, f in FAMILIES.items() if getattr(f, fact))
