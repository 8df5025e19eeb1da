"""Who is on the radio (pure; the caller passes the time): drones' certificates learned from
certificate beacons, their beacon keys from signed beacons, checked position beacons, and the
drones we ignore.

A position beacon counts only if the certificate for its sender's node id is trusted
(:class:`~companion.auth.TrustStore`); if it is signed, by that certificate's key; if it is
tagged, by the pairwise key of the sender's beacon key and ours
(:mod:`companion.neighbours.beacon`); its time within ``max_skew_s`` of ours and its (time,
counter) above the last one accepted from that drone (remembered on disk, so a replay after our
restart is dropped too).  A node id is held by the first trusted drone heard on it; another drone
claiming it is refused while the first one is still heard (a certified drone cannot squat an
address another is using).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from companion.auth.beacon_keys import BeaconKeys
from companion.auth.certificate import Certificate
from companion.auth.trust import Operator, TrustStore, UntrustedPeer
from companion.neighbours.beacon import Beacon, BeaconError, CertBeacon, SignedBeacon, decode_beacon
from companion.state import StateStore

HOLD_NODE_S = 120.0  # a node id stays with its drone this long after it was last heard
NO_CERTIFICATE = "no certificate"
NO_TAG = "no tag for us"
# It tagged for us before under the same keys, so it has our beacon key: it has only not
# heard us lately (its tags are for neighbours heard within the silence period) -- any beacon
# of ours will do, no signed one needed.  Once only: a second beacon without it asks again.
UNHEARD = "no tag for us lately"


class Heard(enum.Enum):
    POSITION = "position"  # a checked, fresh position beacon of a trusted drone
    CERTIFICATE = "certificate"  # a trusted drone's certificate
    UNKNOWN = "unknown"  # a beacon we cannot check yet (no certificate, no beacon key, no tag
    # for us): ask for certificates and signed beacons
    UNTRUSTED = "untrusted"  # a drone the trust store does not accept: ignored
    REJECTED = "rejected"  # malformed, forged, stale or replayed: dropped


@dataclass
class Neighbour:
    """A trusted drone: its certificate, the operator vouching for it, its beacon key and keys
    hash (from its last signed beacon), our tag keys with it."""

    cert: Certificate
    operator: Operator
    last_heard: float
    beacon_key: bytes | None = None
    keys_hash: bytes | None = None
    send_key: bytes | None = None  # our tags for it
    receive_key: bytes | None = None  # its tags for us
    knows_us: bool = False  # a tagged beacon of its carried a tag for us: it has our key
    tagged_us: bool = False  # one of its beacons under its present key did (knows_us once)
    untagged: int = 0  # its beacons without a tag for us since the last with one

    @property
    def fingerprint(self) -> bytes:
        return self.cert.fingerprint


@dataclass(frozen=True, slots=True)
class Hearing:
    kind: Heard
    node: int
    beacon: Beacon | None = None  # POSITION (and UNTRUSTED, when its signature verified)
    neighbour: Neighbour | None = None  # POSITION, CERTIFICATE
    want: bool = False  # CERTIFICATE: the sender asks for ours
    new_keys: bool = False  # POSITION: a beacon key we did not have (it may lack ours)
    cert: Certificate | None = None  # UNTRUSTED: the certificate refused
    reason: str = ""  # UNKNOWN, UNTRUSTED, REJECTED
    then: Hearing | None = None  # CERTIFICATE: its signed beacon heard before, now checked


class Neighbours:
    def __init__(
        self,
        trust: TrustStore,
        store: StateStore,
        me: Certificate,
        keys: BeaconKeys,
        max_skew_s: float = 30.0,
    ) -> None:
        self.trust, self.store, self.me, self.keys = trust, store, me, keys
        self.max_skew_s = max_skew_s
        self._by_node: dict[int, Neighbour] = {}
        self._untrusted: dict[int, Certificate] = {}
        self._waiting: dict[int, bytes] = {}  # a signed beacon heard before its certificate

    def get(self, node: int) -> Neighbour | None:
        return self._by_node.get(node)

    def untrusted(self, node: int) -> bool:
        """A drone on ``node`` showed a certificate the store refuses (and no trusted one)."""
        return node in self._untrusted and node not in self._by_node

    def tag_keys(self, since: float) -> list[bytes]:
        """Our tag keys for the neighbours heard since ``since``, most recent first."""
        heard = sorted(self._by_node.values(), key=lambda n: -n.last_heard)
        return [n.send_key for n in heard if n.send_key is not None and n.last_heard >= since]

    def hear(self, src: int, payload: bytes, now: float) -> Hearing:
        """What a beacon payload from node ``src`` heard at Unix time ``now`` is."""
        try:
            decoded = decode_beacon(payload)
        except BeaconError as exc:
            return Hearing(Heard.REJECTED, src, reason=str(exc))
        if isinstance(decoded, CertBeacon):
            return self._certificate(src, decoded, now)
        known = self._by_node.get(src)
        if known is None:
            refused = self._untrusted.get(src)
            if (
                refused is not None
                and isinstance(decoded, SignedBeacon)
                and decoded.signed_by(src, refused.drone)
            ):
                return Hearing(Heard.UNTRUSTED, src, decoded.beacon, cert=refused)
            if refused is not None and not isinstance(decoded, SignedBeacon):
                return Hearing(Heard.UNTRUSTED, src, cert=refused)  # (tags are not for us)
            # A signed beacon not the untrusted drone's: somebody whose certificate we lack --
            # a made-up certificate for its node id must not make us ignore it: ask.
            if isinstance(decoded, SignedBeacon):  # checked once its certificate comes
                self._waiting.pop(src, None)
                self._waiting[src] = payload
                while len(self._waiting) > 16:
                    del self._waiting[next(iter(self._waiting))]
            return Hearing(Heard.UNKNOWN, src, reason=NO_CERTIFICATE)
        if isinstance(decoded, SignedBeacon):
            if not decoded.signed_by(src, known.cert.drone):
                return Hearing(Heard.REJECTED, src, reason="signature does not verify")
            mine = known.receive_key is not None and decoded.tagged_for(src, known.receive_key)
        elif known.receive_key is None:
            return Hearing(Heard.UNKNOWN, src, reason="no beacon key")
        elif not decoded.tagged_for(src, known.receive_key):
            # no tag for us: it lacks our beacon key or has not heard us lately (or a
            # forger): ask, do not use it
            known.knows_us = False
            known.untagged += 1
            lately = known.tagged_us and known.untagged == 1
            return Hearing(Heard.UNKNOWN, src, reason=UNHEARD if lately else NO_TAG)
        else:
            mine = True
        beacon = decoded.beacon
        if abs(beacon.time - now) > self.max_skew_s:
            return Hearing(Heard.REJECTED, src, reason=f"time {beacon.time - now:+.0f} s off")
        order = beacon.time << 8 | beacon.counter
        last = self.store.last_counter(known.fingerprint)
        if last is not None and order <= last:
            return Hearing(Heard.REJECTED, src, reason="not newer than the last (a replay)")
        self.store.set_counter(known.fingerprint, order)
        known.last_heard = now
        known.knows_us = mine
        new_keys = False
        if isinstance(decoded, SignedBeacon) and decoded.beacon_key != known.beacon_key:
            pair = self.keys.pair(self.me.fingerprint, known.fingerprint, decoded.beacon_key)
            if pair is None:
                return Hearing(Heard.REJECTED, src, reason="beacon key not usable")
            known.send_key, known.receive_key = pair
            known.beacon_key, new_keys = decoded.beacon_key, True
            known.knows_us = decoded.tagged_for(src, known.receive_key)
            known.tagged_us = False  # (a new key of its: it may lack ours)
        if known.knows_us:
            known.tagged_us, known.untagged = True, 0
        if isinstance(decoded, SignedBeacon):
            known.keys_hash = decoded.keys_hash
        return Hearing(Heard.POSITION, src, beacon, known, new_keys=new_keys)

    def _certificate(self, src: int, beacon: CertBeacon, now: float) -> Hearing:
        cert = beacon.cert
        try:
            operator = self.trust.check(cert, src, now)
        except UntrustedPeer as exc:
            if cert.node == src and src not in self._by_node:
                self._untrusted[src] = cert  # to recognise (and report) its beacons
            return Hearing(Heard.UNTRUSTED, src, cert=cert, reason=exc.reason.value)
        known = self._by_node.get(src)
        if known is not None and known.cert.drone != cert.drone:
            if now - known.last_heard < HOLD_NODE_S:
                return Hearing(
                    Heard.REJECTED, src, reason="node id in use by another trusted drone"
                )
            known = None
        if known is None:
            known = self._by_node[src] = Neighbour(cert, operator, now)
            self._untrusted.pop(src, None)
        else:
            known.cert, known.operator = cert, operator  # a renewed certificate
        waiting = self._waiting.pop(src, None)
        then = self.hear(src, waiting, now) if waiting is not None else None
        return Hearing(Heard.CERTIFICATE, src, neighbour=known, want=beacon.want, then=then)
