"""Beacon keys: the X25519 key a drone makes at every start, and the pairwise tag keys it
gives with each neighbour's (:mod:`companion.neighbours.beacon`, tagged beacons).

Both drones of a pair compute the same two keys, one per direction, from X25519 of their
beacon keys (each announced in a signed beacon, so each key is bound to a certified drone),
with HKDF-SHA256 over both fingerprints and both public keys.  Nobody else can compute them:
a tag under the sender-to-us key is as good as the sender's signature, for us.
"""

from __future__ import annotations

from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PrivateKey, X25519PublicKey
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

_INFO = b"pdc/beacon-tags/v1"


class BeaconKeys:
    def __init__(self) -> None:
        self._key = X25519PrivateKey.generate()
        self.public = self._key.public_key().public_bytes(
            serialization.Encoding.Raw, serialization.PublicFormat.Raw
        )

    def pair(self, own: bytes, peer: bytes, peer_public: bytes) -> tuple[bytes, bytes] | None:
        """(our-to-peer key, peer-to-our key) for fingerprints ``own`` and ``peer``; None if
        the peer's beacon key is not a usable X25519 key."""
        try:
            shared = self._key.exchange(X25519PublicKey.from_public_bytes(peer_public))
        except ValueError:
            return None
        ours_first = (own, self.public) < (peer, peer_public)
        first, second = ((own, self.public), (peer, peer_public))[:: 1 if ours_first else -1]
        info = _INFO + first[0] + second[0] + first[1] + second[1]
        okm = HKDF(hashes.SHA256(), 64, salt=None, info=info).derive(shared)
        forward, backward = okm[:32], okm[32:]  # first -> second, second -> first
        return (forward, backward) if ours_first else (backward, forward)
