"""Link frames: a 12-byte header, the payload and a CRC-32 (pure; strict decoding).

::

    0         1..2  3..4  5..6     7    8..9   10..11  12..          last 4
    ver|ty|fl src   dst   session  seq  index  count   payload       CRC-32 (IEEE)

Byte 0 holds the version (2 bits, 1), the frame type (3 bits) and the flags (3 bits): 16
bytes of overhead per frame, 6-7 % of a 222-byte frame's airtime at every spreading factor.
``seq`` numbers the messages of one session and direction; ``index``/``count`` place a DATA
fragment in its message.  Every field is fixed-width and big-endian.  A frame that fails any
check raises :class:`FrameError` with a short ``reason`` that receivers count; nothing else
escapes.
"""

from __future__ import annotations

import enum
import struct
import zlib
from dataclasses import dataclass

from companion.errors import CompanionError
from companion.radio.airtime import PHY_MAX_FRAME

VERSION = 1
HEADER = struct.Struct(">BHHHBHH")
CRC = struct.Struct(">I")
OVERHEAD = HEADER.size + CRC.size  # 16 bytes per frame
BROADCAST = 0xFFFF
MAX_ACK_BITMAP = 32  # bytes: an ACK can report 256 fragments beyond the cumulative point
MAX_BEACON_FRAGMENTS = 8  # a beacon is one frame, or a few on a dwell-limited profile
ABORT_PROOFS = (0, 16, 64)  # none, a keyed session's MAC, a signature (before the keys)


class FrameType(enum.IntEnum):
    DATA = 1  # one fragment of a message
    ACK = 2  # selective acknowledgement: cumulative count + bitmap
    POLL = 3  # "send me your ACK for this message" (after a timeout)
    ABORT = 4  # the session is over on the sender's side; payload: a code (and a proof)
    BEACON = 5  # periodic announcement (fragment index/count), payload opaque to the link


class AbortCode(enum.IntEnum):
    """Why a session ended: one byte, no text (an abort must never carry anything secret, and
    nobody acts on an unauthenticated one beyond ending the run)."""

    PROTOCOL = 1  # the peer's message failed the protocol's checks
    TIMEOUT = 2  # a time limit of the run passed
    SHUTDOWN = 3  # the process is stopping
    REFUSED = 4  # not now
    LINK = 5  # the link gave up (retries exhausted)
    AUTH = 6  # a message failed authentication


class Flag(enum.IntFlag):
    NONE = 0
    ACK_REQ = 1  # DATA: the receiver should acknowledge now (end of a burst)
    COMPLETE = 2  # ACK: the whole message was received (and delivered)


_ALLOWED_FLAGS = {
    FrameType.DATA: Flag.ACK_REQ,
    FrameType.ACK: Flag.COMPLETE,
    FrameType.POLL: Flag.NONE,
    FrameType.ABORT: Flag.NONE,
    FrameType.BEACON: Flag.NONE,
}


class FrameError(CompanionError):
    """A received frame is invalid; ``reason`` is a short counter name."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Frame:
    type: FrameType
    src: int
    dst: int
    session: int
    seq: int = 0
    index: int = 0
    count: int = 1
    payload: bytes = b""
    flags: Flag = Flag.NONE

    def encode(self) -> bytes:
        first = (VERSION << 6) | (self.type << 3) | self.flags
        header = HEADER.pack(
            first, self.src, self.dst, self.session, self.seq, self.index, self.count
        )
        body = header + self.payload
        return body + CRC.pack(zlib.crc32(body))


def decode_frame(data: bytes, max_size: int = PHY_MAX_FRAME) -> Frame:
    """Parse and check one received frame."""
    if len(data) < OVERHEAD:
        raise FrameError("truncated", f"{len(data)} bytes")
    if len(data) > max_size:
        raise FrameError("oversized", f"{len(data)} > {max_size} bytes")
    body, (crc,) = data[: -CRC.size], CRC.unpack(data[-CRC.size :])
    if zlib.crc32(body) != crc:
        raise FrameError("crc")
    first, src, dst, session, seq, index, count = HEADER.unpack_from(body)
    version, kind_code, flags = first >> 6, (first >> 3) & 0x07, first & 0x07
    if version != VERSION:
        raise FrameError("version", str(version))
    try:
        kind = FrameType(kind_code)
    except ValueError:
        raise FrameError("type", str(kind_code)) from None
    if flags & ~_ALLOWED_FLAGS[kind]:
        raise FrameError("flags", f"{flags:#x} on {kind.name}")
    payload = body[HEADER.size :]
    if src == BROADCAST or src == dst:
        raise FrameError("fields", "bad source address")
    if count == 0 or index >= count:
        raise FrameError("fields", f"fragment {index}/{count}")
    if kind is FrameType.DATA and not payload and count != 1:
        raise FrameError("fields", "empty fragment")
    if kind is FrameType.ACK:
        if not 3 <= len(payload) <= 3 + MAX_ACK_BITMAP:
            raise FrameError("fields", "ACK payload size")
        if int.from_bytes(payload[1:3], "big") > count:
            raise FrameError("fields", "ACK beyond count")
    if kind is FrameType.POLL and (payload or index):
        raise FrameError("fields", "POLL carries no payload")
    if kind is FrameType.ABORT and (
        len(payload) - 1 not in ABORT_PROOFS or payload[0] not in AbortCode._value2member_map_
    ):
        raise FrameError("fields", "ABORT payload")
    if kind is FrameType.BEACON and (not payload or count > MAX_BEACON_FRAGMENTS):
        raise FrameError("fields", "BEACON fragment")
    if dst == BROADCAST and kind is not FrameType.BEACON:
        raise FrameError("fields", f"broadcast {kind.name}")
    return Frame(kind, src, dst, session, seq, index, count, bytes(payload), Flag(flags))


@dataclass(frozen=True, slots=True)
class AckInfo:
    """``cumulative`` fragments 0..c-1 received; bit i of ``bitmap`` is fragment c + 1 + i.

    ``epoch`` (1..255) names the receiver's copy of the partial message, 0 means it holds
    none: an ACK under a new epoch tells the sender the receiver started over.
    """

    cumulative: int
    bitmap: bytes = b""
    epoch: int = 0

    def encode(self) -> bytes:
        return bytes([self.epoch]) + self.cumulative.to_bytes(2, "big") + self.bitmap

    @classmethod
    def decode(cls, payload: bytes) -> AckInfo:
        return cls(int.from_bytes(payload[1:3], "big"), payload[3:], payload[0])

    @classmethod
    def of(cls, received: set[int] | frozenset[int], count: int, epoch: int = 0) -> AckInfo:
        cumulative = 0
        while cumulative in received:
            cumulative += 1
        beyond = [i - cumulative - 1 for i in received if i > cumulative]
        span = min((max(beyond) // 8 + 1) if beyond else 0, MAX_ACK_BITMAP)
        bitmap = bytearray(span)
        for bit in beyond:
            if bit < 8 * span:
                bitmap[bit // 8] |= 1 << (bit % 8)
        return cls(min(cumulative, count), bytes(bitmap), epoch)

    def received(self) -> list[int]:
        """Fragment indices this ACK confirms."""
        got = list(range(self.cumulative))
        for bit in range(8 * len(self.bitmap)):
            if self.bitmap[bit // 8] >> (bit % 8) & 1:
                got.append(self.cumulative + 1 + bit)
        return got


def abort_payload(code: AbortCode, proof: bytes = b"") -> bytes:
    """A code, and for an authenticated session the proof that its sender ends it (16 or 64
    bytes, :meth:`companion.auth.session._Party.abort_proof`)."""
    if len(proof) not in ABORT_PROOFS:
        raise ValueError(f"an abort proof is one of {ABORT_PROOFS[1:]} bytes")
    return bytes([code]) + proof
