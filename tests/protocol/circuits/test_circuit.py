"""The circuit builder: levels, schedule and plain evaluation."""

from __future__ import annotations

import itertools

import pytest

from protocol.circuits.boolean import Circuit, Op
from protocol.errors import LocalProtocolError


def test_gates_and_levels() -> None:
    c = Circuit()
    a, b, d = c.input(), c.input(), c.input()
    x = c.xor(a, b)
    y = c.and_(x, d)
    z = c.or_(y, a)
    w = c.and_all([a, b, d, x])
    c.output(z)
    c.output(w)
    assert c.level[x] == 0 and c.level[y] == 1 and c.level[z] == 2 and c.level[w] == 2
    assert c.depth == 2 and c.and_count == 5
    for bits in itertools.product((0, 1), repeat=3):
        p, q, r = bits
        assert c.evaluate(list(bits)) == [int(((p ^ q) & r) | p), p & q & r & (p ^ q)]
    plan = c.schedule()
    assert len(plan) == 3 and not plan[0][0]
    assert all(c.gates[g].op is Op.AND for level in plan for g in level[0])


def test_or_all_and_misuse() -> None:
    c = Circuit()
    ins = [c.input() for _ in range(5)]
    c.output(c.or_all(ins))
    for bits in itertools.product((0, 1), repeat=5):
        assert c.evaluate(list(bits)) == [int(any(bits))]
    with pytest.raises(LocalProtocolError):
        c.and_(ins[0], ins[0])
    with pytest.raises(LocalProtocolError):
        c.and_all([])
    with pytest.raises(LocalProtocolError):
        c.evaluate([0])
