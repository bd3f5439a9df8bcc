"""The contract every registered effect keeps, as checks any effect can be run through (as
scikit-learn's ``check_estimator``): it refuses a bad value of any declared parameter with
a one-line ValueError naming the field; it survives its dict, its JSON and the simulator's
params file unchanged; it simulates the same numbers step by step (``start``) as over a
whole run (``over_time``); its fitter finds it again on a recording simulated with it.
Each check raises AssertionError saying what is broken.  test/effects/test_contract.py
runs them on every registered effect; a new effect can be run through them as it is
written (docs/diagnosis.md, "Adding an effect")."""
from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .. import effects as fx
from .. import simconfig
from ..effects import Stage
from ..effects.base import Candidate, Effect, Param
from ..gap.target import Target
from .protocols import (CONFIG, closed_loop_protocol, recorded, stationary_protocol, sweep,
                        tracked)


def _fields(effect: Effect) -> dict[str, Any]:
    return {f.name: getattr(effect, f.name) for f in dataclasses.fields(effect)}


# -- (a) validation ----------------------------------------------------------------------

def bad_values(spec: Param, value: Any) -> list[Any]:
    """Values the declaration ``spec`` refuses: out of range, of the wrong type or length."""
    bounds = [spec.low - 1 if spec.low is not None else None,
              spec.high + 1 if spec.high is not None else None, spec.above]
    out: list[Any] = {'float': ['x', None, True, math.nan, math.inf],
                      'int': ['x', None, True, 1.5],
                      'bool': ['yes', 1, None],
                      'choice': ['nonsense', None],
                      'sensors': [(-1,), (0.5,), (True,), 'x', 3],
                      'groups': [((),), ((-1, 2),), (5,), 'x'],
                      'floats': [('x',), (math.nan,), 1.0, 'x']}[spec.kind]
    if spec.kind in ('float', 'int'):
        out += [b for b in bounds if b is not None]
    if spec.kind == 'floats':
        out += [(b,) * max(len(value), 1) for b in bounds if b is not None]
        if spec.ascending:
            out.append((2.0, 1.0))
        if spec.per_sensor:
            out.append(tuple(value) + (1.0,))
    return out


def check_validation(cls: type[Effect], example: Effect) -> None:
    """Every declared parameter refuses each bad value with a one-line ValueError that
    names it; the example itself and an unknown field are handled."""
    specs = cls.params()
    fields = _fields(example)
    assert set(specs) == set(fields), f'{cls.name}: fields {sorted(fields)} but declared ' \
                                      f'{sorted(specs)}'
    for name, spec in specs.items():
        assert spec.doc and spec.allowed(), f'{cls.name}.{name}: no doc or allowed values'
        for bad in bad_values(spec, fields[name]):
            try:
                cls(**{**fields, name: bad})
            except ValueError as exc:
                message = str(exc)
                assert '\n' not in message, f'{cls.name}.{name}={bad!r}: not one line: ' \
                                            f'{message!r}'
                assert re.search(rf'\b{name}\b', message), \
                    f'{cls.name}.{name}={bad!r}: the error does not name the field: {message!r}'
            else:
                raise AssertionError(f'{cls.name}: {name}={bad!r} accepted')
    try:
        cls.from_fields({**example.to_dict(), 'wobble': 1})
    except ValueError as exc:
        assert 'wobble' in str(exc) and '\n' not in str(exc), str(exc)
    else:
        raise AssertionError(f'{cls.name}: an unknown field accepted')


# -- (b) round trips ---------------------------------------------------------------------

def check_round_trip(cls: type[Effect], example: Effect, folder: Path) -> None:
    """The dict, the JSON list and fitted_params.yaml give back an equal effect."""
    data = example.to_dict()
    assert data['name'] == cls.name, data
    back = fx.from_dict(json.loads(json.dumps(data)))
    assert type(back) is cls and back == example, f'{cls.name}: dict round trip gave {back!r}'
    assert fx.loads(fx.dumps([example])) == (example,), f'{cls.name}: dumps/loads differ'
    json.dumps(example.parameters())           # diagnosis.json carries them
    config = simconfig.SimConfig(effects=(example,))
    path = simconfig.write(config, folder / f'{cls.name}.yaml')
    loaded = simconfig.load(path)
    assert loaded == config, f'{cls.name}: fitted_params.yaml gave {loaded.effects!r}'


# -- (c) the two paths -------------------------------------------------------------------

def levels(effect: Effect, held: bool, seed: int = 0) -> np.ndarray:
    """(samples, channels, robots) levels: light or readings, or commanded turns in degrees
    (one channel) for an actuator effect; ``held``: runs of one light (a replay's)."""
    rng = np.random.default_rng(seed)
    if effect.stage is Stage.ACTUATOR:
        level = rng.uniform(-30.0, 30.0, (40, 1, 3))
    else:
        level = rng.uniform(20.0, 520.0, (40, 8, 3))
    return np.repeat(level[::10], 10, axis=0) if held else level


def check_paths(cls: type[Effect], example: Effect) -> None:
    """``start`` stepped over the samples gives what ``over_time`` gives, from one seed,
    and neither changes its input."""
    for held in (False, True):
        level = levels(example, held)
        kept = level.copy()
        step = example.start(level.shape[2], level.shape[1], np.random.default_rng(7))
        if example.stage is Stage.ACTUATOR:
            stepwise = np.stack([step(level[t, 0]) for t in range(level.shape[0])])[:, None]
        else:
            stepwise = np.stack([step(level[t]) for t in range(level.shape[0])])
        whole = example.over_time(level, np.random.default_rng(7))
        assert np.array_equal(level, kept), f'{cls.name}: a path changed its input'
        assert whole.shape == level.shape, f'{cls.name}: over_time gave {whole.shape}'
        assert np.allclose(stepwise, whole, rtol=1e-10, atol=1e-9), \
            f'{cls.name}: start and over_time differ by up to ' \
            f'{np.max(np.abs(stepwise - whole)):.3g} (held light: {held})'


# -- (d) the fitter finds its own effect -------------------------------------------------

class FitCase(NamedTuple):
    truth: Effect
    closed_loop: bool                  # the recording: closed loop (turns), else stationary
    parameters: dict[str, tuple[Any, float]]   # value and tolerance of the main parameters
    tracked: bool = False              # the closed loop with its headings (turns measured)
    sweep: float = 0.0                 # stationary: placements every this many degrees


def simulated_target(truth: Effect, closed_loop: bool, headings: bool = False,
                     step: float = 0.0) -> Target:
    """A recording simulated with ``truth``, held as the real data against the plain
    simulator."""
    if step:
        real = recorded(sweep(step), [truth], seed=5)
    elif headings:
        real = tracked(closed_loop_protocol(16), [truth], seed=6)
    elif closed_loop:
        real = recorded(closed_loop_protocol(16), [truth], seed=6)
    else:
        real = recorded(stationary_protocol(samples=20), [truth], seed=5)
    return Target([real], CONFIG, 1, replicates=60)


def check_fit(cls: type[Effect], case: FitCase) -> None:
    """The fitter, on a recording simulated with ``case.truth``, locates it where it was
    and recovers its main parameters within their tolerances; a model of what is left
    (no parameters to recover) must bring the simulator closer."""
    target = simulated_target(case.truth, case.closed_loop, case.tracked, case.sweep)
    cand = cls.fit(target.evidence(target.compare(replicates=40)))
    assert isinstance(cand, Candidate) and cand.name == cls.name and cand.note, cand
    assert isinstance(cand.effect, cls), f'{cls.name}: the fit gave {cand.effect!r} ' \
                                         f'({cand.note})'
    if not case.parameters:
        before, after = target.objective([]), target.objective([cand.effect])
        assert after < before, f'{cls.name}: objective {before:.1f} -> {after:.1f}'
        return
    assert cand.effect.location == case.truth.location, \
        f'{cls.name}: located at {cand.effect.location}, not {case.truth.location}'
    for name, (value, tolerance) in case.parameters.items():
        got = getattr(cand.effect, name)
        ok = got == value if tolerance == 0 else np.allclose(got, value, rtol=0,
                                                             atol=tolerance)
        assert ok, f'{cls.name}: {name} {got!r}, not {value!r} +- {tolerance}'
