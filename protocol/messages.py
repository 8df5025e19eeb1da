"""The path protocol's wire format: versioned, numbered frames with fixed-width fields.

Frame::

    magic "PD" (2) | version (1) | type (1) | step (1) | body length (3, big-endian) | body

``step`` counts the messages of a run from 1 (HELLO); a receiver accepts exactly the type and
step its state machine expects next, so a late or repeated message is refused by name.  Every
body is a concatenation of fixed-width fields whose sizes follow from public values already
agreed (grid, padded path sizes, suite parameters); the decoder checks everything and raises
:class:`~protocol.errors.RemoteProtocolError` and nothing else.  ``docs/wire-format.md`` lists
every message.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import CROSSING, VolumeSpec
from protocol.wire.encoding import Reader

MAGIC = b"PD"
VERSION = 4
HEADER_SIZE = 8
MAX_BODY = (1 << 24) - 1
NONCE_SIZE = 16


class MsgType(enum.IntEnum):
    HELLO = 1  # Alice -> Bob: suite, grid, m, horizon, n asked, nonce, suite offer
    # OT suite (compact)
    OFFER = 2  # Bob -> Alice: n, nonce, setup reply, OT extension, product choice bits
    PRODUCTS = 3  # Alice -> Bob: OT products (shares of every compared value)
    DIGITS = 4  # Bob -> Alice: comparison digit choice bits
    TABLES = 5  # Alice -> Bob: comparison leaf tables, first circuit round
    ROUND = 6  # either way: openings of the circuit's AND levels; Bob's last: output shares
    # paper suite (Paillier + DGK)
    KEYS = 7  # Bob -> Alice: n, keys, encrypted path
    MASKED = 8  # Alice -> Bob: masked orientation / projection values (Paillier)
    BITS = 9  # Bob -> Alice: DGK-encrypted low bits of every masked value
    TESTS = 10  # Alice -> Bob: Veugen's blinded tests
    GATES_IN = 11  # Bob -> Alice: encrypted shares for one AND level
    GATES_OUT = 12  # Alice -> Bob: masked gate outputs for one AND level
    OPEN = 13  # Bob -> Alice: Bob's shares of Alice's result bits


class Suite(enum.IntEnum):
    """Cipher suites."""

    COMPACT = 1  # OT extension on secp256k1 base OTs: products, millionaires, Beaver triples
    PAPER = 2  # Paillier-2048 + DGK-2048 (t = 224): the paper's design, at 112 bits

    @property
    def label(self) -> str:
        return {Suite.COMPACT: "compact", Suite.PAPER: "paper"}[self]


def frame(kind: MsgType, step: int, body: bytes) -> bytes:
    if len(body) > MAX_BODY:
        raise LocalProtocolError("message body too large")
    if not 1 <= step <= 255:
        raise LocalProtocolError("a run has at most 255 messages")
    return MAGIC + bytes([VERSION, kind, step]) + len(body).to_bytes(3, "big") + body


def peek(data: bytes) -> tuple[int, int]:
    """(type, step) of a frame, after checking magic and version."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise RemoteProtocolError("expected bytes")
    if len(data) < HEADER_SIZE:
        raise RemoteProtocolError("frame shorter than its header")
    if bytes(data[:2]) != MAGIC:
        raise RemoteProtocolError("bad magic")
    if data[2] != VERSION:
        raise RemoteProtocolError(f"unsupported protocol version {data[2]}")
    return data[3], data[4]


def unframe(data: bytes, expected: MsgType, step: int) -> bytes:
    """The body of a frame of type ``expected`` and number ``step``; strict about the header."""
    kind, number = peek(data)
    if kind != expected or number != step:
        name = MsgType(kind).name if kind in MsgType._value2member_map_ else str(kind)
        raise RemoteProtocolError(
            f"expected message {step} ({expected.name}), got message {number} ({name})"
        )
    length = int.from_bytes(data[5:8], "big")
    if length != len(data) - HEADER_SIZE:
        raise RemoteProtocolError("frame length does not match its header")
    return bytes(data[HEADER_SIZE:])


def put_blob(blob: bytes) -> bytes:
    if len(blob) > 0xFFFF:
        raise LocalProtocolError("field longer than 65535 bytes")
    return len(blob).to_bytes(2, "big") + blob


def take_blob(reader: Reader) -> bytes:
    return reader.take(reader.uint(2))


@dataclass(frozen=True, slots=True)
class Hello:
    """Message 1.  ``offer`` is the suite's own part (the OT setup, see the suite modules);
    ``horizon_m`` asks Bob to compare only his next ``horizon_m`` metres of path (0: all);
    ``n`` asks him for exactly that many segments, his path cut or padded to them (0: his
    own padded size) -- a size Alice chose from public facts, so that the run's size, which
    every listener reads, shows nothing of his path; ``volumes`` are the run's public volume
    parameters (all zero: the crossing test)."""

    suite: Suite
    kappa: int
    grid: GridSpec
    m: int
    horizon_m: int
    nonce: bytes
    offer: bytes = b""
    volumes: VolumeSpec = CROSSING
    n: int = 0

    def to_bytes(self) -> bytes:
        if len(self.nonce) != NONCE_SIZE:
            raise LocalProtocolError("hello nonce must be 16 bytes")
        body = (
            bytes([self.suite, self.kappa])
            + self.grid.to_bytes()
            + self.m.to_bytes(2, "big")
            + self.horizon_m.to_bytes(4, "big")
            + self.n.to_bytes(2, "big")
            + self.volumes.to_bytes()
            + self.nonce
            + put_blob(self.offer)
        )
        return frame(MsgType.HELLO, 1, body)

    @classmethod
    def from_bytes(cls, data: bytes) -> Hello:
        reader = Reader(unframe(data, MsgType.HELLO, 1))
        code = reader.uint(1)
        try:
            suite = Suite(code)
        except ValueError:
            raise RemoteProtocolError(f"unknown suite {code}") from None
        kappa = reader.uint(1)
        grid = GridSpec.from_bytes(reader.take(GridSpec.SIZE))
        m = reader.uint(2)
        horizon = reader.uint(4)
        n = reader.uint(2)
        volumes = VolumeSpec.read(reader)
        nonce = reader.take(NONCE_SIZE)
        offer = take_blob(reader)
        reader.finish()
        return cls(suite, kappa, grid, m, horizon, nonce, offer, volumes, n)
