"""Fixed-width bit fields: round trips and strict decoding."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.wire.bitpack import pack, packed_size, unpack


@given(
    st.lists(st.integers(0, 70).flatmap(lambda w: st.tuples(st.just(w), st.integers(0, 2**w - 1))))
)
def test_round_trip(fields: list[tuple[int, int]]) -> None:
    widths = [w for w, _ in fields]
    values = [v for _, v in fields]
    data = pack(values, widths)
    assert len(data) == packed_size(widths)
    assert unpack(data, widths) == values


def test_strict() -> None:
    data = pack([5, 1], [3, 2])  # 7 bits -> one byte, one padding bit
    with pytest.raises(RemoteProtocolError):
        unpack(data + b"\x00", [3, 2])
    with pytest.raises(RemoteProtocolError):
        unpack(bytes([data[0] | 1]), [3, 2])
    with pytest.raises(LocalProtocolError):
        pack([8], [3])
    with pytest.raises(LocalProtocolError):
        pack([1, 2], [3])
