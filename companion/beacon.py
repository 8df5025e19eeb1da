"""Beacons: what a drone announces on the radio every few seconds (pure, fixed width).

::

    version u8 | flags u8 | suites u8 | lat i32 (degE7) | lon i32 | alt i16 (m AMSL)
    | mission_version u16 | levels u8 | instance 8 B

24 bytes, one frame at every profile.  ``flags`` bit 0: on the ground (about to take off).
The position is coarse operational information of the kind Remote ID broadcasts anyway; the
*path* is never in a beacon.  ``levels``: bit L set if the drone flies some of its remaining
path L offsets above its plan (:mod:`companion.levels`) -- its altitude shows that anyway.
``instance`` is random per companion start: a peer whose instance changed has lost the OT
setups it shared with us, so we drop ours (identities and signatures: a later issue).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from protocol.wire import Suite

VERSION = 2
_FORMAT = struct.Struct(">BBBiihHB8s")
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
    instance: bytes
    levels: int = 0

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
            self.levels & 0xFF,
            self.instance,
        )

    @classmethod
    def decode(cls, data: bytes) -> Beacon:
        if len(data) != SIZE:
            raise BeaconError(f"beacon of {len(data)} bytes, expected {SIZE}")
        fields = _FORMAT.unpack(data)
        version, flags, mask, lat, lon, alt, mission_version, levels, instance = fields
        if version != VERSION or flags & ~ON_GROUND or mask == 0 or mask & ~0b11:
            raise BeaconError("unknown beacon version, flags or suites")
        if levels & 1:
            raise BeaconError("level 0 is not a climb")
        if abs(lat) > 900_000_000 or abs(lon) > 1_800_000_000:
            raise BeaconError("beacon position out of range")
        suites = frozenset(s for s in Suite if mask >> (s - 1) & 1)
        return cls(
            lat, lon, alt, bool(flags & ON_GROUND), suites, mission_version, instance, levels
        )


def alice_of(a: tuple[bool, int], b: tuple[bool, int]) -> int:
    """Which of two drones is Alice, from (on_ground, node id) each -- both sides agree.

    The drone about to take off is Alice (it adjusts before it is airborne); if both or
    neither are on the ground, the lower node id is.  Exactly one drone of a pair is Alice.
    """
    (a_ground, a_id), (b_ground, b_id) = a, b
    if a_ground != b_ground:
        return a_id if a_ground else b_id
    return min(a_id, b_id)
