"""Shared fixtures: one real 2048-bit key set per test session (112-bit parameters)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pytest

from protocol.dgk import DGKPrivateKey, DGKPublicKey
from protocol.ecelgamal import ECPrivateKey, ECPublicKey
from protocol.paillier import PaillierPrivateKey, PaillierPublicKey


@dataclass(frozen=True)
class Keys:
    """Bob's private keys, and Alice's copies of the public keys decoded from bytes."""

    paillier: PaillierPrivateKey
    dgk: DGKPrivateKey
    ec: ECPrivateKey
    paillier_pub: PaillierPublicKey
    dgk_pub: DGKPublicKey
    ec_pub: ECPublicKey

    def backend(self, name: str) -> tuple[Any, Any]:
        """(Bob's zero-test private key, Alice's public view) for 'ec' or 'dgk'."""
        if name == "ec":
            return self.ec, self.ec_pub
        return self.dgk, self.dgk_pub


@pytest.fixture(scope="session")
def keys() -> Keys:
    paillier = PaillierPrivateKey.generate()
    dgk = DGKPrivateKey.generate()
    ec = ECPrivateKey.generate()
    return Keys(
        paillier,
        dgk,
        ec,
        PaillierPublicKey.from_bytes(paillier.public_key.to_bytes()),
        DGKPublicKey.from_bytes(dgk.public_key.to_bytes()),
        ECPublicKey.from_bytes(ec.public_key.to_bytes()),
    )


@dataclass(frozen=True)
class PathKeys:
    """Long-lived keys of two drones for the path protocol (both suites)."""

    bob: Any  # protocol.intersection.BobKeys
    alice: dict[Any, Any]  # Suite -> Alice's zero-test private key


@pytest.fixture(scope="session")
def path_keys(keys: Keys) -> PathKeys:
    from protocol.intersection import DGK_COUNT_BITS, BobKeys
    from protocol.wire import Suite

    bob = BobKeys(keys.paillier, {Suite.COMPACT: keys.ec, Suite.PAPER: keys.dgk})
    alice = {
        Suite.COMPACT: ECPrivateKey.generate(),
        Suite.PAPER: DGKPrivateKey.generate(comparison_bits=DGK_COUNT_BITS),
    }
    return PathKeys(bob, alice)
