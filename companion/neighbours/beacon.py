"""Beacons: what a drone announces on the radio every few seconds (pure, fixed width).

Every position beacon starts with the same 26 bytes::

    head u8 | flags u8 | lat i32 (degE7) | lon i32 | alt i16 (m AMSL) | mission_version u16
    | slot base u16 | slot mask u32 | size_class u8 | time u32 (Unix s) | counter u8

and is authenticated in one of two ways:

* **signed** (138 + 4 k bytes): ``body | beacon key (32) | keys_hash (16) | Ed25519
  signature (64) | k tags`` -- signed under the key the sender's certificate names (the tags,
  as below, tell each neighbour that the sender holds its key).  It carries the sender's
  *beacon key*, an X25519 key made at every start, and ``keys_hash``, the hash of all its
  public protocol keys (its per-start nonce, the beacon key, the paper suite's keys:
  :func:`keys_hash`).  Sent at
  the start, when a new drone asks, when the sender learns a new neighbour, and every few
  minutes.
* **tagged** (26 + 4 k bytes): ``body | k tags of 4 bytes`` -- one per neighbour whose beacon
  key the sender holds and that it heard lately, most recent first (at most 16, so a tagged
  beacon is never larger than a signed one; with 8, format 6, each drone of ten in range left
  one neighbour out of every beacon, and that one could not check it): HMAC-SHA256 under a
  key only the two of them can compute (X25519 of their beacon keys, per direction), cut to
  4 bytes, as LoRaWAN's and Bluetooth's message integrity codes are.  A receiver checks the
  tag meant for it (it tries the k): a forger's beacon passes with probability k / 2^32 per
  transmission, one frame on the air per try (``docs/security.md``); a beacon costs 4 bytes
  per neighbour where a signature is 64.

The receiver drops a beacon it cannot check, whose time is more than the allowed skew off its
clock, or whose (time, counter) is not above the last one it accepted from that drone (a
replay; remembered on disk).  The time travels whole (Unix seconds, good until 2106): a
beacon recorded any time before is stale for ever -- with only its low 16 bits (until format
5) a beacon recorded 65,536 s earlier read as fresh, and its old beacon key then made the
drone's genuine beacons look like replays.

Certificate beacon (117 bytes): ``head | flags | certificate``
(:mod:`companion.auth.certificate`); flag WANT: the sender heard a beacon it could not check
and asks the drones nearby for their certificates and signed beacons.

``head``: the format version (7) in the high nibble, the kind in the low one.  Position
flags: bit 0 on the ground (about to take off), bits 1-2 the cipher suites offered.
``size_class``: the remaining path's padded size is at most 2^size_class segments (a run
asking for more is refused before any work).  ``mission_version``: a digest of the path as
flown in four dimensions (ground track, altitudes, schedule epoch): a peer compares again
when it changes.  The slots: the 5 m altitude slots the remaining path occupies as flown
(:class:`companion.mission.levels.Slots`), for peers that must keep clear of them.  The position is
coarse operational information of the kind Remote ID broadcasts anyway; the *path* is never
in a beacon.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
from dataclasses import dataclass
from enum import StrEnum

from companion.auth.certificate import SIZE as CERT_SIZE
from companion.auth.certificate import Certificate, CertificateError
from companion.auth.keys import SIGNATURE_SIZE, PublicKey, SigningKey
from companion.errors import CompanionError
from companion.mission.levels import Slots
from protocol.messages import Suite

VERSION = 7  # 7: up to 16 tags (6: 8)
SIGNED, CERTIFICATE, TAGGED = 1, 2, 3
KEYS_HASH_SIZE = 16
BEACON_KEY_SIZE = 32
TAG_SIZE = 4
MAX_TAGS = 16  # 26 + 4 x 16 = 90 bytes: a tagged beacon stays below a signed one (138)
_BODY = struct.Struct(">BBiihHHIBIB")
BODY_SIZE = _BODY.size  # 26
SIGNED_SIZE = BODY_SIZE + BEACON_KEY_SIZE + KEYS_HASH_SIZE + SIGNATURE_SIZE  # 138
CERT_BEACON_SIZE = 2 + CERT_SIZE  # 117
UNAUTHENTICATED_SIZE = 24  # what a beacon was before it was authenticated (for the costs)
ON_GROUND = 0x01
WANT = 0x01
MAX_SIZE_CLASS = 8  # 256 segments
_CONTEXT = b"pdc/beacon/v1"


class BeaconKind(StrEnum):
    """What a beacon we send is (counted per kind)."""

    SIGNED = "signed"  # a position beacon signed with our drone key
    TAGGED = "tagged"  # a position beacon with a tag for each neighbour
    CERTIFICATE = "certificate"  # our operator's certificate


class BeaconError(CompanionError):
    """A received beacon is malformed."""


def keys_hash(boot: bytes, beacon_key: bytes, protocol_keys: bytes) -> bytes:
    """What signed beacons announce of a drone's public protocol keys: its per-start nonce,
    its beacon key, its paper-suite keys (:meth:`protocol.intersection.BobKeys.public_bytes`,
    or nothing).  A run's keys must match it (:mod:`companion.auth.session`)."""
    data = b"pdc/keys/v1" + boot + beacon_key + protocol_keys
    return hashlib.sha256(data).digest()[:KEYS_HASH_SIZE]


@dataclass(frozen=True, slots=True)
class Beacon:
    lat: int
    lon: int
    alt_m: int
    on_ground: bool
    suites: frozenset[Suite]
    mission_version: int
    time: int  # Unix seconds
    counter: int
    slots: Slots = Slots()  # noqa: RUF009 (frozen: immutable)
    size_class: int = MAX_SIZE_CLASS

    def body(self, kind: int) -> bytes:
        mask = 0
        for suite in self.suites:
            mask |= 1 << (suite - 1)
        flags = (ON_GROUND if self.on_ground else 0) | mask << 1
        return _BODY.pack(
            VERSION << 4 | kind,
            flags,
            self.lat,
            self.lon,
            max(-32768, min(32767, self.alt_m)),
            self.mission_version & 0xFFFF,
            self.slots.base,
            self.slots.mask,
            self.size_class,
            self.time & 0xFFFFFFFF,
            self.counter & 0xFF,
        )

    def signed(
        self,
        node: int,
        key: SigningKey,
        beacon_key: bytes,
        keys: bytes,
        tag_keys: list[bytes] | tuple[()] = (),
    ) -> bytes:
        """The signed form: announces the beacon key and the keys hash (and tags for the
        neighbours whose keys we hold)."""
        head = self.body(SIGNED) + beacon_key + keys
        signed = head + key.sign(_CONTEXT + node.to_bytes(2, "big") + head)
        return signed + b"".join(beacon_tag(k, node, head) for k in tag_keys[:MAX_TAGS])

    def tagged(self, node: int, tag_keys: list[bytes]) -> bytes:
        """The tagged form: one tag per neighbour key (at most MAX_TAGS)."""
        body = self.body(TAGGED)
        return body + b"".join(beacon_tag(k, node, body) for k in tag_keys[:MAX_TAGS])


def beacon_tag(key: bytes, node: int, body: bytes) -> bytes:
    mac = hmac.new(key, _CONTEXT + node.to_bytes(2, "big") + body, hashlib.sha256)
    return mac.digest()[:TAG_SIZE]


@dataclass(frozen=True)
class TaggedBeacon:
    beacon: Beacon
    body: bytes  # what the tags (and a signature) cover
    tags: tuple[bytes, ...]

    def tagged_for(self, node: int, key: bytes) -> bool:
        """A tag under ``key`` (the sender-to-us key) is among the tags."""
        mine = beacon_tag(key, node, self.body)
        return any(hmac.compare_digest(mine, tag) for tag in self.tags)


@dataclass(frozen=True)
class SignedBeacon(TaggedBeacon):
    beacon_key: bytes = b""
    keys_hash: bytes = b""
    signature: bytes = b""

    def signed_by(self, node: int, key: PublicKey) -> bool:
        return key.verify(self.signature, _CONTEXT + node.to_bytes(2, "big") + self.body)


@dataclass(frozen=True, slots=True)
class CertBeacon:
    cert: Certificate
    want: bool = False

    def encode(self) -> bytes:
        return bytes([VERSION << 4 | CERTIFICATE, WANT if self.want else 0]) + self.cert.encode()


def _body(data: bytes) -> Beacon:
    fields = _BODY.unpack(data[:BODY_SIZE])
    _, flags, lat, lon, alt, version, base, slots, size_class, time, counter = fields
    mask = flags >> 1
    if flags & ~0b111 or mask == 0:
        raise BeaconError("unknown beacon flags or suites")
    if size_class > MAX_SIZE_CLASS:
        raise BeaconError(f"size class {size_class} above {MAX_SIZE_CLASS}")
    if abs(lat) > 900_000_000 or abs(lon) > 1_800_000_000:
        raise BeaconError("beacon position out of range")
    suites = frozenset(s for s in Suite if mask >> (s - 1) & 1)
    return Beacon(
        lat,
        lon,
        alt,
        bool(flags & ON_GROUND),
        suites,
        version,
        time,
        counter,
        Slots(base, slots),
        size_class,
    )


def decode_beacon(data: bytes) -> SignedBeacon | TaggedBeacon | CertBeacon:
    """Parse a beacon payload (nothing checked yet but its form); :class:`BeaconError`."""
    data = bytes(data)
    if not data or data[0] >> 4 != VERSION:
        raise BeaconError("unknown beacon version")
    kind = data[0] & 0x0F
    if kind == CERTIFICATE:
        if len(data) != CERT_BEACON_SIZE or data[1] & ~WANT:
            raise BeaconError("malformed certificate beacon")
        try:
            return CertBeacon(Certificate.decode(data[2:]), bool(data[1] & WANT))
        except CertificateError as exc:
            raise BeaconError(str(exc)) from None
    if kind not in (SIGNED, TAGGED):
        raise BeaconError(f"unknown beacon kind {kind}")
    fixed = SIGNED_SIZE if kind == SIGNED else BODY_SIZE
    count, extra = divmod(len(data) - fixed, TAG_SIZE)
    if len(data) < fixed or extra or count > MAX_TAGS:
        raise BeaconError(f"beacon of {len(data)} bytes")
    tags = tuple(data[fixed + TAG_SIZE * i : fixed + TAG_SIZE * (i + 1)] for i in range(count))
    beacon = _body(data)
    if kind == TAGGED:
        return TaggedBeacon(beacon, data[:BODY_SIZE], tags)
    head = data[: SIGNED_SIZE - SIGNATURE_SIZE]
    key = head[BODY_SIZE : BODY_SIZE + BEACON_KEY_SIZE]
    signature = data[len(head) : SIGNED_SIZE]
    return SignedBeacon(beacon, head, tags, key, head[-KEYS_HASH_SIZE:], signature)


def alice_of(a: tuple[bool, int], b: tuple[bool, int]) -> int:
    """Which of two drones is Alice, from (on_ground, node id) each -- both sides agree.

    The drone about to take off is Alice (it adjusts before it is airborne); if both or
    neither are on the ground, the lower node id is.  Exactly one drone of a pair is Alice.
    """
    (a_ground, a_id), (b_ground, b_id) = a, b
    if a_ground != b_ground:
        return a_id if a_ground else b_id
    return min(a_id, b_id)


def size_class(segments: int) -> int:
    """The smallest c with 2^c >= segments (the beacon's path size class)."""
    return max(segments - 1, 0).bit_length()
