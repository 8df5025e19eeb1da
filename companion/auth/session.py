"""Authenticated, protected runs (sans-IO): a signed ephemeral key exchange on the run's
first two messages, then ChaCha20-Poly1305 on every message, bound to the whole transcript.

The design is SIGMA-I (the signed Diffie-Hellman of IKEv2 and TLS 1.3) folded into the path
protocol's own first round trip, so authentication costs no extra radio turn:

====  ===========  ==================================================================
 1    A -> B       ``0x01 | A's fingerprint (8) | time u32 | eA (32) | sig_A (64) | HELLO``
 2    B -> A       ``0x02 | eB (32) | sig_B (64) | AEAD(boot (16) | cover u8 | first reply)``, or
                   ``0x03 | code u8 | sig_B (64)``: a signed refusal (:class:`Refusal`)
 3..  either way   ``AEAD(message)``: 16-byte tag
====  ===========  ==================================================================

* sig_A covers the route (both node ids and the link session id), both fingerprints, the time,
  eA and the HELLO's hash: Bob knows who asks, that the request is fresh (time within the skew;
  the caller keeps a replay cache of (fingerprint, eA)) and meant for him, *before* he spends
  anything on it.  The HELLO itself travels in the clear: its fields (grid, sizes, horizon,
  base-OT points) are public to Bob and uniform or bucketed (``docs/security.md``).
* sig_B covers th2 = H(th1, eB), th1 the hash of message 1 and the route: Alice knows Bob
  answered this very request.  Keys: HKDF-SHA256(X25519(eA, eB), salt th2) -> one key per
  direction; nonces count messages per direction.
* Every AEAD's associated data is the running hash of everything before it (message 1, eB,
  every earlier ciphertext), so a forged, replayed, reordered or spliced message fails its
  tag: :class:`AuthenticationError`, and the run ends with no result.
* An abort carries a proof that it is the peer's (:meth:`_Party.abort_proof`): once the keys
  exist a 16-byte HMAC-SHA256 under a key derived from the sender's direction key; before,
  an Ed25519 signature over the request's hash and the code (64 bytes).  Only the two
  parties can end a run (the link ignores an ABORT without a proof that checks,
  :meth:`companion.radio.LinkEndpoint.secure`).
* ``boot`` is the responder's per-start nonce; with his public protocol keys it is what his
  signed beacons' keys hash covers (:func:`companion.neighbours.beacon.keys_hash`): the initiator
  checks the keys of the run against the keys he announced.  ``cover`` is the responder's
  one byte about his answer: the companion's near-run cover of the horizon asked, in eighths
  (``companion.mission.ground.near_answer``).

Errors: anything wrong with an authenticated message raises :class:`AuthenticationError` (a
:class:`~protocol.errors.RemoteProtocolError`); nothing else escapes.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import struct
from dataclasses import dataclass

from cryptography.exceptions import InvalidTag
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PrivateKey, X25519PublicKey
from cryptography.hazmat.primitives.ciphers.aead import ChaCha20Poly1305
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

from companion.auth.certificate import Certificate
from companion.auth.keys import FINGERPRINT_SIZE, SIGNATURE_SIZE, SigningKey
from companion.errors import CompanionError
from protocol.errors import RemoteProtocolError

CONTEXT = b"pdc/session/v1/"
INIT, ACCEPT, REFUSE = 1, 2, 3
EPHEMERAL_SIZE = 32
BOOT_SIZE = 16
TAG_SIZE = 16
_INIT_HEAD = struct.Struct(f">B{FINGERPRINT_SIZE}sI{EPHEMERAL_SIZE}s{SIGNATURE_SIZE}s")
ACCEPT_OVERHEAD = 1 + EPHEMERAL_SIZE + SIGNATURE_SIZE + TAG_SIZE + BOOT_SIZE + 1  # 130 bytes
REFUSE_SIZE = 2 + SIGNATURE_SIZE
ABORT_PROOF_SIZE = 16


class AuthenticationError(CompanionError, RemoteProtocolError):
    """A message of the run failed authentication (signature, tag, freshness, identity)."""


class Refusal(enum.IntEnum):
    """Why a responder declines a run; signed, so the initiator may act on it."""

    ROLE = 1  # I am Alice for this pair already (the lower node id keeps the role)
    UNKNOWN_SETUP = 2  # your hello names an OT setup I do not hold: start a fresh one
    BUDGET = 3  # you (or your operator, or everybody) used up the runs for this hour
    SIZE = 4  # your path is larger than your beacon or your operator's limit allows
    BUSY = 5  # not now
    UNKNOWN_PEER = 6  # I hold no certificate of yours yet: beacon it, then ask again
    BOX = 7  # your grid is not centred where your beacons say you are


@dataclass(frozen=True, slots=True)
class Identity:
    """Our signing key and the certificate our operator issued for it."""

    key: SigningKey
    cert: Certificate

    def __post_init__(self) -> None:
        if self.key.public != self.cert.drone:
            raise ValueError("the certificate is for another key")

    @property
    def fingerprint(self) -> bytes:
        return self.cert.fingerprint


@dataclass(frozen=True, slots=True)
class Route:
    """Where a run travels: the initiator's and responder's node ids and the link session."""

    initiator: int
    responder: int
    session: int

    def encode(self) -> bytes:
        return struct.pack(">HHH", self.initiator, self.responder, self.session)


@dataclass(frozen=True, slots=True)
class Init:
    """Message 1, parsed but not yet verified (parsing costs nothing)."""

    fingerprint: bytes
    time: int
    ephemeral: bytes
    signature: bytes
    hello: bytes
    raw: bytes

    @classmethod
    def parse(cls, data: bytes) -> Init:
        if len(data) < _INIT_HEAD.size or data[0] != INIT:
            raise AuthenticationError("not a run request")
        _, fpr, time, ephemeral, signature = _INIT_HEAD.unpack_from(data)
        return cls(fpr, time, ephemeral, signature, bytes(data[_INIT_HEAD.size :]), bytes(data))

    @property
    def replay_key(self) -> bytes:
        """What a replay cache remembers: a request is answered once."""
        return self.fingerprint + self.ephemeral


@dataclass(frozen=True, slots=True)
class Accepted:
    boot: bytes
    cover: int
    payload: bytes


@dataclass(frozen=True, slots=True)
class Refused:
    code: Refusal


def _h(*parts: bytes) -> bytes:
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part)
    return digest.digest()


def _init_signed(
    route: Route, a: bytes, b: bytes, time: int, ephemeral: bytes, hello: bytes
) -> bytes:
    return (
        CONTEXT + b"init" + route.encode() + a + b + time.to_bytes(4, "big") + ephemeral + _h(hello)
    )


def _th1(route: Route, msg1: bytes) -> bytes:
    return _h(CONTEXT, b"th1", route.encode(), msg1)


def _th2(th1: bytes, eb: bytes) -> bytes:
    return _h(CONTEXT, b"th2", th1, eb)


def _ephemeral() -> tuple[X25519PrivateKey, bytes]:
    key = X25519PrivateKey.generate()
    return key, key.public_key().public_bytes(
        serialization.Encoding.Raw, serialization.PublicFormat.Raw
    )


def _derive(own: X25519PrivateKey, peer: bytes, th2: bytes) -> tuple[bytes, bytes]:
    """(initiator -> responder key, responder -> initiator key)."""
    try:
        shared = own.exchange(X25519PublicKey.from_public_bytes(peer))
    except ValueError:  # a low-order point: the shared secret would be all zeros
        raise AuthenticationError("peer's ephemeral key is not acceptable") from None
    okm = HKDF(hashes.SHA256(), 64, salt=th2, info=CONTEXT + b"keys").derive(shared)
    return okm[:32], okm[32:]


class _Channel:
    """ChaCha20-Poly1305 both ways after the handshake; AD = the running transcript hash."""

    def __init__(self, send_key: bytes, receive_key: bytes, transcript: bytes) -> None:
        self._send, self._receive = ChaCha20Poly1305(send_key), ChaCha20Poly1305(receive_key)
        self._abort_send, self._abort_receive = _abort_key(send_key), _abort_key(receive_key)
        self._sent = self._received = 0
        self._th = transcript
        self.failed = False

    def seal(self, payload: bytes) -> bytes:
        if self.failed:
            raise AuthenticationError("the session failed authentication")
        out = self._send.encrypt(self._sent.to_bytes(12, "big"), payload, self._th)
        self._sent += 1
        self._th = _h(self._th, out)
        return out

    def open(self, data: bytes) -> bytes:
        if self.failed:
            raise AuthenticationError("the session failed authentication")
        try:
            payload = self._receive.decrypt(
                self._received.to_bytes(12, "big"), bytes(data), self._th
            )
        except (InvalidTag, ValueError):
            self.failed = True
            raise AuthenticationError("message failed authentication") from None
        self._received += 1
        self._th = _h(self._th, bytes(data))
        return payload

    def abort_proof(self, code: int) -> bytes:
        return _abort_mac(self._abort_send, code)

    def abort_checks(self, code: int, proof: bytes) -> bool:
        return hmac.compare_digest(_abort_mac(self._abort_receive, code), bytes(proof))


def _abort_key(direction_key: bytes) -> bytes:
    return hmac.new(direction_key, CONTEXT + b"abort-key", hashlib.sha256).digest()


def _abort_mac(key: bytes, code: int) -> bytes:
    return hmac.new(key, CONTEXT + b"abort" + bytes([code]), hashlib.sha256).digest()[
        :ABORT_PROOF_SIZE
    ]


class _Party:
    """Seal and open once the key exchange has made the session's channel."""

    _channel: _Channel | None

    def seal(self, payload: bytes) -> bytes:
        if self._channel is None:
            raise AuthenticationError("no session yet")
        return self._channel.seal(payload)

    def open(self, data: bytes) -> bytes:
        if self._channel is None:
            raise AuthenticationError("no session yet")
        return self._channel.open(data)

    @property
    def keyed(self) -> bool:
        """The key exchange is done: the run's messages are sealed from now on."""
        return self._channel is not None

    _th1: bytes
    me: Identity
    _signs_as: bytes  # what our signed aborts say we are: b"i" or b"r"

    def abort_proof(self, code: int) -> bytes:
        """What proves our abort of this session to the peer: the channel's MAC once the keys
        exist, before them a signature over the request's hash and the code."""
        if self._channel is not None:
            return self._channel.abort_proof(code)
        if not self._th1:
            return b""
        return self.me.key.sign(_abort_signed(self._signs_as, self._th1, code))

    def abort_checks(self, code: int, proof: bytes) -> bool:
        """Whether an abort's ``proof`` is the peer's (the channel's MAC, or the peer's
        signature over the request's hash and the code)."""
        if len(proof) == ABORT_PROOF_SIZE:
            return self._channel is not None and self._channel.abort_checks(code, proof)
        peer = self._peer_cert()
        if len(proof) != SIGNATURE_SIZE or peer is None or not self._th1:
            return False
        theirs = b"r" if self._signs_as == b"i" else b"i"
        return peer.drone.verify(bytes(proof), _abort_signed(theirs, self._th1, code))

    def _peer_cert(self) -> Certificate | None:
        raise NotImplementedError


def _abort_signed(who: bytes, th1: bytes, code: int) -> bytes:
    return CONTEXT + b"abort/" + who + th1 + bytes([code])


class Initiator(_Party):
    """Alice's side: wraps her HELLO, checks Bob's answer, then seals and opens."""

    _signs_as = b"i"

    def __init__(self, me: Identity, peer: Certificate, route: Route, unix_s: float) -> None:
        self.me, self.peer, self.route = me, peer, route
        self.time = int(unix_s)
        self._key, self._public = _ephemeral()
        self._th1 = b""
        self._channel: _Channel | None = None

    def first(self, hello: bytes) -> bytes:
        signed = _init_signed(
            self.route, self.me.fingerprint, self.peer.fingerprint, self.time, self._public, hello
        )
        head = _INIT_HEAD.pack(
            INIT, self.me.fingerprint, self.time, self._public, self.me.key.sign(signed)
        )
        msg1 = head + hello
        self._th1 = _th1(self.route, msg1)
        return msg1

    def reply(self, data: bytes) -> Accepted | Refused:
        """Bob's answer to message 1: his first protocol reply, or a signed refusal."""
        if not self._th1 or self._channel is not None:
            raise AuthenticationError("no request is waiting for an answer")
        if len(data) == REFUSE_SIZE and data[0] == REFUSE:
            signed = CONTEXT + b"refuse" + self._th1 + data[1:2]
            if not self.peer.drone.verify(bytes(data[2:]), signed):
                raise AuthenticationError("refusal not signed by the peer")
            try:
                return Refused(Refusal(data[1]))
            except ValueError:
                raise AuthenticationError(f"unknown refusal code {data[1]}") from None
        if len(data) < ACCEPT_OVERHEAD or data[0] != ACCEPT:
            raise AuthenticationError("not an answer to this request")
        eb = bytes(data[1 : 1 + EPHEMERAL_SIZE])
        signature = bytes(data[1 + EPHEMERAL_SIZE : 1 + EPHEMERAL_SIZE + SIGNATURE_SIZE])
        th2 = _th2(self._th1, eb)
        signed = CONTEXT + b"accept" + th2 + self.me.fingerprint + self.peer.fingerprint
        if not self.peer.drone.verify(signature, signed):
            raise AuthenticationError("answer not signed by the peer")
        to_peer, from_peer = _derive(self._key, eb, th2)
        self._channel = _Channel(to_peer, from_peer, th2)
        inner = self._channel.open(bytes(data[1 + EPHEMERAL_SIZE + SIGNATURE_SIZE :]))
        return Accepted(inner[:BOOT_SIZE], inner[BOOT_SIZE], inner[BOOT_SIZE + 1 :])

    def _peer_cert(self) -> Certificate | None:
        return self.peer


class Responder(_Party):
    """Bob's side: parses message 1, verifies it (before any protocol work), then answers."""

    _signs_as = b"r"

    def __init__(self, me: Identity, init: Init, route: Route) -> None:
        self.me, self.init, self.route = me, init, route
        self._th1 = _th1(route, init.raw)
        self._channel: _Channel | None = None
        self.peer: Certificate | None = None
        self.answered = False

    def verify(
        self, peer: Certificate, arrived_s: float, max_skew_s: float, max_wait_s: float = 0.0
    ) -> None:
        """Check the request comes from ``peer``, for us, and is fresh: made at most
        ``max_skew_s`` after and ``max_skew_s + max_wait_s`` before it began to arrive
        (Unix seconds; ``max_wait_s``: how long a sender's first frame may wait for its
        duty-cycle budget).  :class:`AuthenticationError` if not."""
        init = self.init
        if init.fingerprint != peer.fingerprint:
            raise AuthenticationError("request from another identity than its certificate's")
        age = arrived_s - init.time
        if not -max_skew_s <= age <= max_skew_s + max_wait_s:
            raise AuthenticationError(f"request made {age:+.0f} s before it arrived")
        signed = _init_signed(
            self.route, peer.fingerprint, self.me.fingerprint, init.time, init.ephemeral, init.hello
        )
        if not peer.drone.verify(init.signature, signed):
            raise AuthenticationError("request signature does not verify")
        self.peer = peer

    def _peer_cert(self) -> Certificate | None:
        return self.peer  # (only a verified requester's signed abort counts)

    def accept(self, boot: bytes, payload: bytes, *, cover: int) -> bytes:
        if self.peer is None:
            raise AuthenticationError("the request was not verified")
        if self.answered:
            raise AuthenticationError("request already answered")
        if len(boot) != BOOT_SIZE:
            raise ValueError("boot nonce of 16 bytes")
        if not 0 <= cover <= 0xFF:
            raise ValueError("cover is one byte")
        self.answered = True
        key, eb = _ephemeral()
        th2 = _th2(self._th1, eb)
        signed = CONTEXT + b"accept" + th2 + self.peer.fingerprint + self.me.fingerprint
        signature = self.me.key.sign(signed)
        from_peer, to_peer = _derive(key, self.init.ephemeral, th2)
        self._channel = _Channel(to_peer, from_peer, th2)
        sealed = self._channel.seal(boot + bytes([cover]) + payload)
        return bytes([ACCEPT]) + eb + signature + sealed

    def refuse(self, code: Refusal) -> bytes:
        """A signed refusal (also to a requester not verified: it only says no)."""
        if self.answered:
            raise AuthenticationError("request already answered")
        self.answered = True
        signed = CONTEXT + b"refuse" + self._th1 + bytes([code])
        return bytes([REFUSE, code]) + self.me.key.sign(signed)
