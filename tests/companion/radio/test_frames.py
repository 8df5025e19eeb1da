"""Frame encoding, strict decoding (fuzzed), acknowledgement bitmaps, COBS."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from companion.radio.frames import (
    BROADCAST,
    MAX_ACK_BITMAP,
    OVERHEAD,
    AbortCode,
    AckInfo,
    Flag,
    Frame,
    FrameError,
    FrameType,
    abort_payload,
    decode_frame,
)
from companion.radio.serial_port import cobs_decode, cobs_encode

node = st.integers(0, BROADCAST - 1)


@st.composite
def data_frames(draw: st.DrawFn) -> Frame:
    src = draw(node)
    dst = draw(node.filter(lambda d: d != src))
    count = draw(st.integers(1, 0xFFFF))
    return Frame(
        FrameType.DATA,
        src,
        dst,
        draw(st.integers(0, 0xFFFF)),
        draw(st.integers(0, 255)),
        draw(st.integers(0, count - 1)),
        count,
        draw(st.binary(min_size=1, max_size=255 - OVERHEAD)),
        draw(st.sampled_from([Flag.NONE, Flag.ACK_REQ])),
    )


@settings(max_examples=300)
@given(data_frames())
def test_round_trip(frame: Frame) -> None:
    raw = frame.encode()
    assert len(raw) == OVERHEAD + len(frame.payload)
    assert decode_frame(raw) == frame


@settings(max_examples=300)
@given(data_frames(), st.data())
def test_any_bit_flip_is_caught(frame: Frame, data: st.DataObject) -> None:
    raw = bytearray(frame.encode())
    bit = data.draw(st.integers(0, 8 * len(raw) - 1))
    raw[bit // 8] ^= 1 << (bit % 8)
    with pytest.raises(FrameError):
        decode_frame(bytes(raw))


@settings(max_examples=300)
@given(data_frames(), st.data())
def test_truncation_is_caught(frame: Frame, data: st.DataObject) -> None:
    raw = frame.encode()
    cut = data.draw(st.integers(0, len(raw) - 1))
    with pytest.raises(FrameError):
        decode_frame(raw[:cut])


@settings(max_examples=2000)
@given(st.binary(max_size=300))
def test_decoder_fuzz_raises_only_frame_error(raw: bytes) -> None:
    try:
        frame = decode_frame(raw)
    except FrameError as exc:
        assert exc.reason in {"truncated", "oversized", "crc", "version", "type", "flags", "fields"}
    else:
        assert frame.encode() == raw


def _sealed(body: bytes) -> bytes:
    import zlib

    return body + zlib.crc32(body).to_bytes(4, "big")


def _hdr(
    kind: int,
    *,
    version: int = 1,
    flags: int = 0,
    src: int = 1,
    dst: int = 2,
    index: int = 0,
    count: int = 1,
) -> bytes:
    first = (version << 6) | (kind << 3) | flags
    return (
        bytes([first])
        + b"".join(v.to_bytes(2, "big") for v in (src, dst, 3))
        + b"\x00"
        + index.to_bytes(2, "big")
        + count.to_bytes(2, "big")
    )


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        (_hdr(1, version=2) + b"x", "version"),
        (_hdr(7) + b"x", "type"),
        (_hdr(0) + b"x", "type"),
        (_hdr(1, flags=2) + b"x", "flags"),  # COMPLETE belongs to ACKs
        (_hdr(1, index=5, count=5) + b"x", "fields"),
        (_hdr(1, dst=1) + b"x", "fields"),  # src = dst
        (_hdr(3) + b"x", "fields"),  # POLL with payload
        (_hdr(2) + b"\x01\x00\x05", "fields"),  # ACK beyond count
        (_hdr(4) + b"\x01\xff", "fields"),  # ABORT text not UTF-8
        (_hdr(1, dst=0xFFFF) + b"x", "fields"),  # broadcast DATA
    ],
)
def test_field_checks(body: bytes, reason: str) -> None:
    with pytest.raises(FrameError) as info:
        decode_frame(_sealed(body))
    assert info.value.reason == reason


def test_oversized_frame_is_refused() -> None:
    frame = Frame(FrameType.DATA, 1, 2, 3, payload=b"x" * 240)
    with pytest.raises(FrameError, match="oversized"):
        decode_frame(frame.encode())


@settings(max_examples=300)
@given(st.integers(1, 600), st.data())
def test_ack_bitmap_reports_exactly_what_fits(count: int, data: st.DataObject) -> None:
    received = data.draw(st.sets(st.integers(0, count - 1)))
    info = AckInfo.of(received, count)
    got = set(info.received())
    assert got <= received
    assert len(info.bitmap) <= MAX_ACK_BITMAP
    reportable = {i for i in received if i < info.cumulative + 1 + 8 * MAX_ACK_BITMAP}
    assert got == reportable
    assert AckInfo.decode(info.encode()) == info


def test_aborts_carry_one_code_and_nothing_else() -> None:
    """No text, nothing secret: an ABORT is one byte from a fixed set, and in a keyed session
    a proof that its sender is the peer (a 16-byte MAC, or before the keys a signature)."""
    for code in AbortCode:
        frame = Frame(FrameType.ABORT, 1, 2, 7, payload=abort_payload(code))
        assert decode_frame(frame.encode()).payload == bytes([code])
        proven = Frame(FrameType.ABORT, 1, 2, 7, payload=abort_payload(code, bytes(range(16))))
        assert decode_frame(proven.encode()).payload == bytes([code, *range(16)])
    with pytest.raises(ValueError, match="proof"):
        abort_payload(AbortCode.AUTH, b"short")
    for payload in (b"", b"\x01text", b"\x00", b"\x63", b"\x01" + bytes(15), b"\x01" + bytes(17)):
        with pytest.raises(FrameError, match="ABORT"):
            decode_frame(Frame(FrameType.ABORT, 1, 2, 7, payload=payload).encode())


@settings(max_examples=500)
@given(st.binary(max_size=700))
def test_cobs_round_trip(data: bytes) -> None:
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert cobs_decode(encoded) == data


@settings(max_examples=500)
@given(st.binary(max_size=300))
def test_cobs_decoder_fuzz(data: bytes) -> None:
    try:
        cobs_decode(data)
    except ValueError:
        pass
