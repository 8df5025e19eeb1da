"""Pools of precomputed encryption noise.

Fresh Paillier noise r^n mod n^2 is the expensive part of an encryption (a 2048-bit exponent
modulo a 4096-bit modulus); DGK noise h^r is the same story at smaller scale.  A pool that was
filled ahead (:meth:`NoisePool.fill`: the benchmark measures that case; the companion does not
fill one yet) turns the online encryption into one modular multiplication; an empty pool
computes noise on demand: slower, never weaker.  Each value is handed out once.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from gmpy2 import mpz


class NoisePool:
    """A FIFO of one-time noise values produced by ``source``."""

    __slots__ = ("_source", "_values")

    def __init__(self, source: Callable[[], mpz]) -> None:
        self._source = source
        self._values: deque[mpz] = deque()

    def fill(self, count: int) -> None:
        """Precompute ``count`` more values (offline work)."""
        for _ in range(count):
            self._values.append(self._source())

    def take(self) -> mpz:
        """One unused noise value: from the pool if any, else freshly computed."""
        if self._values:
            return self._values.popleft()
        return self._source()

    def __len__(self) -> int:
        return len(self._values)
