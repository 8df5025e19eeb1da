"""Beacons: what a drone announces on the radio every few seconds (pure, fixed width).

::

    version u8 | flags u8 | suites u8 | lat i32 (degE7) | lon i32 | alt i16 (m AMSL)
    | mission_version u16 | key fingerprint 8 B

25 bytes, one frame at every profile.  ``flags`` bit 0: on the ground (about to take off).
The position is coarse operational information of the kind Remote ID broadcasts anyway; the
*path* is never in a beacon.  The fingerprint (SHA-256 of the drone's public keys, 8 bytes)
lets a peer bind a session to the keys it heard announced.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass

from protocol.wire import Suite

VERSION = 1
_FORMAT = struct.Struct(">BBBiihH8s")
SIZE = _FORMAT.size
ON_GROUND = 0x01


class BeaconError(ValueError):
    """A received beacon is malformed."""


@dataclass(frozen=True, slots=True)
class Beacon:
    lat: int
    lon: int
    alt_m: int
    on_ground: bool
    suites: frozenset[Suite]
    mission_version: int
    fingerprint: bytes

    def encode(self) -> bytes:
        mask = 0
        for suite in self.suites:
            mask |= 1 << (suite - 1)
        flags = ON_GROUND if self.on_ground else 0
        return _FORMAT.pack(
            VERSION,
            flags,
            mask,
            self.lat,
            self.lon,
            max(-32768, min(32767, self.alt_m)),
            self.mission_version & 0xFFFF,
            self.fingerprint,
        )

    @classmethod
    def decode(cls, data: bytes) -> Beacon:
        if len(data) != SIZE:
            raise BeaconError(f"beacon of {len(data)} bytes, expected {SIZE}")
        version, flags, mask, lat, lon, alt, mission_version, fingerprint = _FORMAT.unpack(data)
        if version != VERSION or flags & ~ON_GROUND or mask == 0 or mask & ~0b11:
            raise BeaconError("unknown beacon version, flags or suites")
        if abs(lat) > 900_000_000 or abs(lon) > 1_800_000_000:
            raise BeaconError("beacon position out of range")
        suites = frozenset(s for s in Suite if mask >> (s - 1) & 1)
        return cls(lat, lon, alt, bool(flags & ON_GROUND), suites, mission_version, fingerprint)


def fingerprint(public_keys: bytes) -> bytes:
    return hashlib.sha256(b"deconfliction-keys-v1" + public_keys).digest()[:8]


def alice_of(a: tuple[bool, int], b: tuple[bool, int]) -> int:
    """Which of two drones is Alice, from (on_ground, node id) each -- both sides agree.

    The drone about to take off is Alice (it adjusts before it is airborne); if both or
    neither are on the ground, the lower node id is.  Exactly one drone of a pair is Alice.
    """
    (a_ground, a_id), (b_ground, b_id) = a, b
    if a_ground != b_ground:
        return a_id if a_ground else b_id
    return min(a_id, b_id)
