"""Base oblivious transfers on secp256k1, receiver first (a Bellare-Micali style DH OT).

A public point h = HashToPoint("pdc/ot/base/h") whose discrete logarithm nobody knows.

1. Receiver, choice sigma_i: random b_i, sends B_i = b_i G + sigma_i h  (uniform for either
   choice: the receiver's choice is perfectly hidden), drawn again until B_i has an even y,
   so that its x alone encodes it (uniform over those points for either choice).
2. Sender: random a (again until A has an even y), sends A = a G; its keys are
   k_i^0 = H(i, A, B_i, a B_i) and k_i^1 = H(i, A, B_i, a (B_i - h)).
3. Receiver: k_i^{sigma_i} = H(i, A, B_i, b_i A), since a (B_i - sigma_i h) = a b_i G.

The other key needs a (B_i -/+ h) = b_i A -/+ a h, i.e. the Diffie-Hellman value of A and h
(CDH); this holds even for a receiver that chose B_i maliciously, since nobody knows log h.
Receiver first means the setup costs no extra round trip: Alice's B_i travel in her HELLO and
Bob's A in his reply.  Only random keys come out; the setup (:mod:`.setup`) uses them as
one-time pads.  Sizes: 32 bytes per B_i, 32 bytes for A (x only).
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence

from protocol.errors import LocalProtocolError, RemoteProtocolError
from protocol.ot.hashing import base_key
from protocol.primitives import secp256k1 as ec
from protocol.wire.encoding import Reader

H = ec.hash_to_point(b"pdc/ot/base/h", b"")


def _scalar() -> int:
    return 1 + secrets.randbelow(ec.ORDER - 1)


class BaseReceiver:
    """Holds choice bits; learns one key per OT."""

    def __init__(self, choices: Sequence[int]) -> None:
        if any(c not in (0, 1) for c in choices):
            raise LocalProtocolError("base OT choices must be bits")
        self.choices = list(choices)
        self._b = [_scalar() for _ in choices]
        self._points: list[bytes] = []
        for i, c in enumerate(self.choices):
            while True:  # about two tries, whatever the choice: each point's parity is a coin
                plain = ec.base_mul(self._b[i])
                shifted = ec.add(plain, H)  # computed for either choice: same work
                point = (plain, shifted)[c]
                if ec.has_even_y(point):
                    break
                self._b[i] = _scalar()
            self._points.append(ec.encode(point))

    def message(self) -> bytes:
        """Step 1: the B_i, 32 bytes each (x only)."""
        return b"".join(point[1:] for point in self._points)

    def keys(self, sender_message: bytes) -> list[bytes]:
        """Step 3: k_i^{sigma_i} from the sender's A."""
        a_point = ec.decode_x(sender_message)
        a_bytes = ec.encode(a_point)
        return [
            base_key(i, a_bytes, point, ec.encode(ec.mul(a_point, b)))
            for i, (b, point) in enumerate(zip(self._b, self._points, strict=True))
        ]


class BaseSender:
    """Learns both keys of every OT from the receiver's points."""

    def __init__(self, receiver_message: bytes, count: int) -> None:
        reader = Reader(receiver_message)
        points = [ec.decode_x(reader.take(ec.X_SIZE)) for _ in range(count)]
        reader.finish()
        while True:
            a = _scalar()
            a_point = ec.base_mul(a)
            if ec.has_even_y(a_point):
                break
        self._a_bytes = ec.encode(a_point)
        ah = ec.mul(H, a)
        self.keys: list[tuple[bytes, bytes]] = []
        for i, point in enumerate(points):
            ab = ec.mul(point, a)
            shifted = ec.add(ab, ec.neg(ah))
            if ab is None or shifted is None:
                raise RemoteProtocolError("base OT point is degenerate")
            raw = ec.encode(point)
            self.keys.append(
                (
                    base_key(i, self._a_bytes, raw, ec.encode(ab)),
                    base_key(i, self._a_bytes, raw, ec.encode(shifted)),
                )
            )

    def message(self) -> bytes:
        """Step 2: A, 32 bytes (x only)."""
        return self._a_bytes[1:]


def message_size(count: int) -> int:
    """Bytes of the receiver's message for ``count`` OTs."""
    return count * ec.X_SIZE
