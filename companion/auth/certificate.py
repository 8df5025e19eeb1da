"""Drone certificates: an operator vouches for a drone's signing key and its radio address.

::

    version u8 (1) | node u16 | drone key (32) | operator fingerprint (8)
    | not_before u32 | not_after u32 (Unix seconds) | operator signature (64)

115 bytes, fixed width.  The signature covers ``b"pdc/cert/v1"`` and every field before it.
The node id is in the certificate so that a drone cannot speak for another address: a beacon
or a run from node X counts only if the certificate that verifies it names X.  A drone is
*identified* by its key (budgets and logs use the key's fingerprint), never by its node id.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from companion.auth.keys import FINGERPRINT_SIZE, PUBLIC_SIZE, SIGNATURE_SIZE, PublicKey, SigningKey
from companion.errors import CompanionError

VERSION = 1
_BODY = struct.Struct(f">BH{PUBLIC_SIZE}s{FINGERPRINT_SIZE}sII")
SIZE = _BODY.size + SIGNATURE_SIZE
_CONTEXT = b"pdc/cert/v1"
MAX_NODE = 0xFFFE  # 0xFFFF is the broadcast address


class CertificateError(CompanionError):
    """A certificate is malformed."""


@dataclass(frozen=True, slots=True)
class Certificate:
    node: int
    drone: PublicKey
    operator: bytes  # the operator key's fingerprint
    not_before: int
    not_after: int
    signature: bytes = b""

    def body(self) -> bytes:
        return _BODY.pack(
            VERSION, self.node, self.drone.raw, self.operator, self.not_before, self.not_after
        )

    @classmethod
    def issue(
        cls, operator: SigningKey, drone: PublicKey, node: int, not_before: int, not_after: int
    ) -> Certificate:
        if not 0 <= node <= MAX_NODE:
            raise CertificateError(f"node id {node} outside 0..{MAX_NODE}")
        if not 0 <= not_before <= not_after < 1 << 32:
            raise CertificateError("validity: not_before <= not_after, both Unix seconds")
        unsigned = cls(node, drone, operator.fingerprint, not_before, not_after)
        return cls(
            node,
            drone,
            operator.fingerprint,
            not_before,
            not_after,
            operator.sign(_CONTEXT + unsigned.body()),
        )

    def encode(self) -> bytes:
        return self.body() + self.signature

    @classmethod
    def decode(cls, data: bytes) -> Certificate:
        if len(data) != SIZE:
            raise CertificateError(f"certificate of {len(data)} bytes, expected {SIZE}")
        version, node, drone, operator, not_before, not_after = _BODY.unpack(data[: _BODY.size])
        if version != VERSION:
            raise CertificateError(f"unknown certificate version {version}")
        if node > MAX_NODE or not_before > not_after:
            raise CertificateError("certificate fields out of range")
        return cls(
            node, PublicKey(drone), operator, not_before, not_after, bytes(data[_BODY.size :])
        )

    def signed_by(self, operator: PublicKey) -> bool:
        return operator.fingerprint == self.operator and operator.verify(
            self.signature, _CONTEXT + self.body()
        )

    def valid_at(self, unix_s: float) -> bool:
        return self.not_before <= unix_s <= self.not_after

    @property
    def fingerprint(self) -> bytes:
        """The drone's identity: its key's fingerprint."""
        return self.drone.fingerprint
