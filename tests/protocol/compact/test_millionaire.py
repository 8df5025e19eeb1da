"""OT millionaires: [b > t] and [b = t] on shares, for every digit size and threshold count."""

from __future__ import annotations

import secrets
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from protocol.compact.millionaire import Shape, digit_widths, digits
from protocol.errors import LocalProtocolError
from protocol.tools.loopback import run_millionaires


def test_digit_widths() -> None:
    assert digit_widths(26, 4) == [2, 4, 4, 4, 4, 4, 4]
    assert digit_widths(8, 4) == [4, 4]
    assert digit_widths(1, 4) == [1]
    assert digits(0b10_1100_0011, [2, 4, 4]) == [0b10, 0b1100, 0b0011]
    with pytest.raises(LocalProtocolError):
        digit_widths(8, 9)


def expected(bob: list[int], alice: list[list[int]]) -> list[int]:
    out = []
    for b, ts in zip(bob, alice, strict=True):
        for t in ts:
            out += [int(b > t), int(b == t)]
    return out


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(l=st.integers(1, 40), w=st.integers(1, 6), data=st.data())
def test_random(ot_pair: Any, l: int, w: int, data: st.DataObject) -> None:
    value = st.integers(0, 2**l - 1)
    bob = data.draw(st.lists(value, min_size=1, max_size=5))
    alice = [
        data.draw(
            st.lists(
                st.one_of(value, st.sampled_from([b, max(b - 1, 0), min(b + 1, 2**l - 1)])),
                min_size=1,
                max_size=3,
            )
        )
        for b in bob
    ]
    shape = Shape.of(l, w, [len(t) for t in alice])
    outputs, _ = run_millionaires(ot_pair.chooser, ot_pair.holder, shape, bob, alice, need_eq=True)
    assert outputs == expected(bob, alice)


@pytest.mark.parametrize("l", [1, 4, 26])
def test_every_boundary(ot_pair: Any, l: int) -> None:
    top = 2**l - 1
    pairs = [(0, 0), (top, top), (0, top), (top, 0), (1, 0), (0, 1), (top, top - 1), (top - 1, top)]
    pairs = [(b, t) for b, t in pairs if 0 <= t <= top and 0 <= b <= top]
    bob = [b for b, _ in pairs]
    alice = [[t] for _, t in pairs]
    shape = Shape.of(l, 4, [1] * len(pairs))
    outputs, _ = run_millionaires(ot_pair.chooser, ot_pair.holder, shape, bob, alice, need_eq=True)
    assert outputs == expected(bob, alice)


def test_sizes_are_public(ot_pair: Any) -> None:
    shape = Shape.of(20, 4, [1, 2])
    runs = []
    for _ in range(2):
        bob = [secrets.randbits(20) for _ in range(2)]
        alice = [[secrets.randbits(20)], [secrets.randbits(20), secrets.randbits(20)]]
        _, transcript = run_millionaires(ot_pair.chooser, ot_pair.holder, shape, bob, alice)
        runs.append(transcript.sizes)
    assert runs[0] == runs[1]
