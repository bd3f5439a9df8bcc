"""Memos of the fast paths: ``once`` for what a target makes once (its protocol's layout),
``Recent`` for what a few simulations share without growing over a long diagnosis."""
from __future__ import annotations

from typing import Callable, Hashable, TypeVar

K = TypeVar('K', bound=Hashable)
V = TypeVar('V')


def once(memo: dict[K, V], key: K, make: Callable[[], V]) -> V:
    """``memo[key]``, made by ``make`` the first time."""
    if key not in memo:
        memo[key] = make()
    return memo[key]


class Recent(dict[K, V]):
    """At most ``keep`` entries; ``recall`` makes a missing one and drops the entry used
    longest ago."""

    def __init__(self, keep: int) -> None:
        super().__init__()
        self.keep = keep

    def recall(self, key: K, make: Callable[[], V]) -> V:
        if key in self:
            value = self.pop(key)              # to the end: used last
        else:
            value = make()
            if len(self) >= self.keep:
                del self[next(iter(self))]
        self[key] = value
        return value
