"""The path protocol's wire format: versioned frames with fixed-width fields.

Frame::

    magic "PD" (2) | version (1) | type (1) | body length (4, big-endian) | body

Every body is a concatenation of fixed-width fields whose sizes follow from public values
already agreed (key sizes, m, n, l); variable parts (public keys) carry a 2-byte length.  The
decoder checks magic, version, the type the state machine expects next, the length, and then
the body field by field (group membership of every ciphertext and point); any mismatch raises
:class:`~protocol.errors.RemoteProtocolError` and nothing else.  ``docs/wire-format.md`` lists
every message.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .encoding import Reader
from .errors import LocalProtocolError, RemoteProtocolError
from .grid import GridSpec

MAGIC = b"PD"
VERSION = 1
HEADER_SIZE = 8
MAX_BODY = 1 << 30


class MsgType(enum.IntEnum):
    HELLO = 1  # Alice -> Bob: suites offered with Alice's keys, kappa, grid, m
    KEYS = 2  # Bob -> Alice: suite chosen, n, Bob's keys, his encrypted path
    MASKED = 3  # Alice -> Bob: packed masked orientation / projection values
    BITS = 4  # Bob -> Alice: encrypted low bits of every masked value
    TESTS = 5  # Alice -> Bob: blinded comparison tests (tokens)
    GATES = 6  # Bob -> Alice: Bob's encrypted shares and share products
    LEVEL1 = 7  # Alice -> Bob: masked s12, s34, col, w (tokens) + Alice's encrypted masks
    COUNTS = 8  # Bob -> Alice: blinded hit counts per Alice segment (tokens)


class Suite(enum.IntEnum):
    """Cipher suites: Paillier-2048 with a zero-test scheme for the comparison bits."""

    COMPACT = 1  # Paillier-2048 + EC-ElGamal on secp256k1 (default)
    PAPER = 2  # Paillier-2048 + DGK-2048, t = 224 (the paper's choice, at 112 bits)

    @property
    def label(self) -> str:
        return {Suite.COMPACT: "compact", Suite.PAPER: "paper"}[self]


def frame(kind: MsgType, body: bytes) -> bytes:
    if len(body) > MAX_BODY:
        raise LocalProtocolError("message body too large")
    return MAGIC + bytes([VERSION, kind]) + len(body).to_bytes(4, "big") + body


def unframe(data: bytes, expected: MsgType) -> bytes:
    """The body of a frame of type ``expected``; strict about everything in the header."""
    if not isinstance(data, bytes | bytearray | memoryview):
        raise RemoteProtocolError("expected bytes")
    data = bytes(data)
    if len(data) < HEADER_SIZE:
        raise RemoteProtocolError("frame shorter than its header")
    if data[:2] != MAGIC:
        raise RemoteProtocolError("bad magic")
    if data[2] != VERSION:
        raise RemoteProtocolError(f"unsupported protocol version {data[2]}")
    if data[3] != expected:
        raise RemoteProtocolError(f"expected message type {expected.name}, got {data[3]}")
    length = int.from_bytes(data[4:8], "big")
    if length > MAX_BODY or length != len(data) - HEADER_SIZE:
        raise RemoteProtocolError("frame length does not match its header")
    return data[HEADER_SIZE:]


def put_blob(blob: bytes) -> bytes:
    if len(blob) > 0xFFFF:
        raise LocalProtocolError("field longer than 65535 bytes")
    return len(blob).to_bytes(2, "big") + blob


def take_blob(reader: Reader) -> bytes:
    return reader.take(reader.uint(2))


@dataclass(frozen=True, slots=True)
class Hello:
    """Message 1.  ``keys`` holds Alice's zero-test public key for each suite offered."""

    suites: tuple[Suite, ...]
    keys: tuple[bytes, ...]
    kappa: int
    grid: GridSpec
    m: int

    def to_bytes(self) -> bytes:
        parts = [bytes([len(self.suites)])]
        for suite, key in zip(self.suites, self.keys, strict=True):
            parts += [bytes([suite]), put_blob(key)]
        parts += [bytes([self.kappa]), self.grid.to_bytes(), self.m.to_bytes(2, "big")]
        return frame(MsgType.HELLO, b"".join(parts))

    @classmethod
    def from_bytes(cls, data: bytes) -> Hello:
        reader = Reader(unframe(data, MsgType.HELLO))
        count = reader.uint(1)
        if not 1 <= count <= len(Suite):
            raise RemoteProtocolError("between one and two suites must be offered")
        suites: list[Suite] = []
        keys: list[bytes] = []
        for _ in range(count):
            code = reader.uint(1)
            try:
                suite = Suite(code)
            except ValueError:
                raise RemoteProtocolError(f"unknown suite {code}") from None
            if suite in suites:
                raise RemoteProtocolError("suite offered twice")
            suites.append(suite)
            keys.append(take_blob(reader))
        kappa = reader.uint(1)
        grid = GridSpec.from_bytes(reader.take(GridSpec.SIZE))
        m = reader.uint(2)
        reader.finish()
        return cls(tuple(suites), tuple(keys), kappa, grid, m)


@dataclass(frozen=True, slots=True)
class KeysHeader:
    """The fixed part of message 2; the encrypted path follows (sizes from n and the key)."""

    suite: Suite
    n: int
    paillier_key: bytes
    bits_key: bytes

    def to_bytes(self) -> bytes:
        return (
            bytes([self.suite])
            + self.n.to_bytes(2, "big")
            + put_blob(self.paillier_key)
            + put_blob(self.bits_key)
        )

    @classmethod
    def read(cls, reader: Reader) -> KeysHeader:
        code = reader.uint(1)
        try:
            suite = Suite(code)
        except ValueError:
            raise RemoteProtocolError(f"unknown suite {code}") from None
        n = reader.uint(2)
        return cls(suite, n, take_blob(reader), take_blob(reader))
