"""Bob's long-term keys for the paper suite: Paillier and DGK (the compact suite needs none)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

from protocol.messages import put_blob
from protocol.paper import keyproof
from protocol.primitives.dgk import DGKPrivateKey
from protocol.primitives.paillier import PaillierPrivateKey

MAX_MODULUS_BITS = 4096  # bounds the work a peer's key can impose
DGK_BITS = 85  # the paper suite's DGK u = 263 holds comparison terms for l <= 86


@dataclass(frozen=True)
class BobKeys:
    """Bob's long-term keys for the paper suite (the compact suite needs none)."""

    paillier: PaillierPrivateKey
    dgk: DGKPrivateKey

    @classmethod
    def generate(cls) -> BobKeys:
        return cls(PaillierPrivateKey.generate(), DGKPrivateKey.generate(comparison_bits=DGK_BITS))

    def public_bytes(self) -> bytes:
        """The public keys as the KEYS message carries them (what a beacon's keys hash
        covers): the Paillier and the DGK public key, each a 2-byte length and its bytes."""
        return put_blob(self.paillier.public_key.to_bytes()) + put_blob(
            self.dgk.public_key.to_bytes()
        )

    @functools.cached_property
    def paillier_proof(self) -> bytes:
        """The proof that the Paillier modulus is fit (:mod:`protocol.paper.keyproof`), made
        once."""
        return keyproof.prove(self.paillier)
