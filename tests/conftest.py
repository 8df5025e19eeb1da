"""Shared fixtures: one real key set and one real OT setup per test session (112-bit floor)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from protocol.dgk import DGKPrivateKey, DGKPublicKey
from protocol.intersection import DGK_BITS, BobKeys
from protocol.ot.setup import ChooserSetup, HolderSetup, HolderSetupStart, chooser_setup
from protocol.paillier import PaillierPrivateKey, PaillierPublicKey


@dataclass(frozen=True)
class Keys:
    """Bob's private keys, and Alice's copies of the public keys decoded from bytes."""

    paillier: PaillierPrivateKey
    dgk: DGKPrivateKey
    paillier_pub: PaillierPublicKey
    dgk_pub: DGKPublicKey

    @property
    def bob(self) -> BobKeys:
        return BobKeys(self.paillier, self.dgk)


@pytest.fixture(scope="session")
def keys() -> Keys:
    paillier = PaillierPrivateKey.generate()
    dgk = DGKPrivateKey.generate(comparison_bits=DGK_BITS)
    return Keys(
        paillier,
        dgk,
        PaillierPublicKey.from_bytes(paillier.public_key.to_bytes()),
        DGKPublicKey.from_bytes(dgk.public_key.to_bytes()),
    )


@dataclass(frozen=True)
class OtPair:
    """One OT setup between two drones: Bob's (chooser) and Alice's (Delta holder) halves."""

    chooser: ChooserSetup
    holder: HolderSetup

    @property
    def setups(self) -> dict[bytes, ChooserSetup]:
        return {self.chooser.setup_id: self.chooser}


@pytest.fixture(scope="session")
def ot_pair() -> OtPair:
    start = HolderSetupStart()
    chooser, reply = chooser_setup(start.message(), start.blocks)
    return OtPair(chooser, start.finish(reply))
