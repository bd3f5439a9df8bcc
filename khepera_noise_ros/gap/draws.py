"""The effects' random draws in a stationary replay, remembered.

``gap.simulate.stationary`` gives the effects one generator per replay, seeded by the
replay's seed alone, and each effect draws whole arrays from it (``over_time``).  A fit
replays the same protocol with the same seed and the same effects but other
parameters, so the same arrays are drawn again and again: drawing a normal costs ten
times copying it.  ``Remembered`` is that generator with a memory: the n-th draw of a
seed's stream after the same n - 1 calls is the same array, kept once (read-only) and
handed out as a copy; the stream goes on from the generator's state after it.
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np

KEPT_BYTES = 96 << 20      # draws kept at most (the oldest go first)
_KEPT: OrderedDict = OrderedDict()     # (entropy, calls) -> (array, state after it)
_SIZE = [0]


class Remembered:
    """``np.random.default_rng(entropy)`` for the calls ``standard_normal(size)`` and
    ``random(size)``, each draw remembered; any other use gets the generator itself,
    at the same point of its stream, and is not remembered."""

    def __init__(self, entropy):
        self._entropy = tuple(int(e) for e in entropy)
        self._calls: tuple = ()
        self._state = None          # the bit generator's state after the calls so far
        self._rng = None            # the generator itself, once a draw is not known

    def standard_normal(self, size=None, **kwargs):
        return self._draw('standard_normal', size, kwargs)

    def random(self, size=None, **kwargs):
        return self._draw('random', size, kwargs)

    def __getattr__(self, name):
        if name.startswith('_'):
            raise AttributeError(name)
        rng = self._generator()
        self._calls = None              # the stream is no longer known by its calls
        return getattr(rng, name)

    def _generator(self) -> np.random.Generator:
        if self._rng is None:
            if self._state is None:
                self._rng = np.random.default_rng(list(self._entropy))
            else:
                bits = np.random.PCG64()
                bits.state = self._state
                self._rng = np.random.Generator(bits)
        return self._rng

    def _draw(self, method: str, size, kwargs: dict) -> np.ndarray:
        if kwargs or size is None or self._calls is None:
            self._calls = None
            return getattr(self._generator(), method)(size, **kwargs)
        calls = self._calls + ((method, _shape(size)),)
        key = (self._entropy, calls)
        if self._rng is None:
            hit = _KEPT.get(key)
            if hit is not None:
                _KEPT.move_to_end(key)
                self._calls, self._state = calls, hit[1]
                return hit[0].copy()
        value = getattr(self._generator(), method)(size)
        self._calls = calls
        _keep(key, value, self._rng.bit_generator.state)
        return value


def _shape(size) -> tuple | None:
    return None if size is None else tuple(int(s) for s in np.atleast_1d(size))


def _keep(key: tuple, value: np.ndarray, state: dict) -> None:
    kept = np.array(value)
    kept.flags.writeable = False
    if kept.nbytes > KEPT_BYTES:
        return
    old = _KEPT.pop(key, None)
    if old is not None:
        _SIZE[0] -= old[0].nbytes
    _KEPT[key] = (kept, state)
    _SIZE[0] += kept.nbytes
    while _SIZE[0] > KEPT_BYTES:
        _, (dropped, _) = _KEPT.popitem(last=False)
        _SIZE[0] -= dropped.nbytes
