"""The OT extension's consistency check: the fields are fields, an honest chooser passes, and a
chooser who deviates -- in his extension message or in the setup's GGM corrections -- is caught
unless he guessed every bit of Delta his deviation depends on (the leakage KOS allows, which
ends the setup when the guess is wrong)."""

from __future__ import annotations

import secrets

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import ConsistencyError
from protocol.ot import check
from protocol.ot.check import FIELDS, Field
from protocol.ot.extension import _expand, _fold, _mask_tail, chooser_extend, holder_extend
from protocol.ot.setup import ChooserSetup, HolderSetup, HolderSetupStart, chooser_setup

pytestmark = pytest.mark.deviating


# --------------------------------------------------------------------------- the fields


def _pmod(a: int, m: int) -> int:
    while a.bit_length() >= m.bit_length():
        a ^= m << (a.bit_length() - m.bit_length())
    return a


def _x_to_2k(k: int, gf: Field) -> int:
    r = 2
    for _ in range(k):
        r = gf.mul(r, r)
    return r


def _gcd(a: int, b: int) -> int:
    while b:
        a, b = b, _pmod(a, b)
    return a


@pytest.mark.parametrize("bits", sorted(FIELDS))
def test_the_moduli_are_irreducible(bits: int) -> None:
    """Rabin's test: x^(2^n) = x mod f, and gcd(x^(2^(n/q)) - x, f) = 1 for each prime q | n."""
    gf = FIELDS[bits]
    assert gf.modulus.bit_length() == bits + 1
    assert _x_to_2k(bits, gf) == 2
    for q in (p for p in (2, 3, 5, 7) if bits % p == 0):
        assert _gcd(gf.modulus, _x_to_2k(bits // q, gf) ^ 2) == 1


@settings(max_examples=50, deadline=None)
@given(st.sampled_from(sorted(FIELDS)), st.data())
def test_field_laws(bits: int, data: st.DataObject) -> None:
    gf = FIELDS[bits]
    a, b, c = (data.draw(st.integers(0, (1 << bits) - 1)) for _ in range(3))
    assert gf.mul(a, b) == gf.mul(b, a) < 1 << bits
    assert gf.mul(a, b ^ c) == gf.mul(a, b) ^ gf.mul(a, c)
    assert gf.mul(gf.mul(a, b), c) == gf.mul(a, gf.mul(b, c))
    assert gf.mul(a, 1) == a and gf.mul(a, 2) == gf.times_x(a)


# --------------------------------------------------------------------------- a deviating Bob


def _pair(kappa: int = 112) -> tuple[ChooserSetup, HolderSetup]:
    from protocol.ot.setup import split_blocks

    start = HolderSetupStart(split_blocks(12, kappa))
    chooser, reply = chooser_setup(start.message(), start.blocks)
    return chooser, start.finish(reply)


def _bob_state(
    setup: ChooserSetup, nonce: bytes, total: int
) -> tuple[list[npt.NDArray[np.uint8]], npt.NDArray[np.uint8], list[npt.NDArray[np.uint8]]]:
    """Bob's columns (t), choice bits and per-block u, as :func:`chooser_extend` makes them."""
    columns, sums = [], []
    for k, leaves in zip(setup.blocks, setup.leaves, strict=True):
        u, v = _fold(_expand(leaves, nonce, (total + 7) // 8), k)
        sums.append(_mask_tail(u, total))
        columns += v
    return columns, sums[0], sums


@pytest.mark.parametrize("kappa", [112, 128])
@settings(max_examples=20, deadline=None)
@given(position=st.integers(0, 10_000), bit=st.integers(0, 7))
def test_any_flipped_bit_of_the_extension_is_caught(kappa: int, position: int, bit: int) -> None:
    chooser, holder = _pair(kappa)
    nonce = secrets.token_bytes(32)
    message, _ = chooser_extend(chooser, nonce, 40)
    tampered = bytearray(message)
    tampered[position % len(message)] ^= 1 << bit
    with pytest.raises(ConsistencyError):
        holder_extend(holder, nonce, 40, bytes(tampered))


def _selective_failure(guess_right: bool) -> bool:
    """Bob flips one OT's correction in block 1 -- Alice's row then carries Delta_1 -- and
    answers the check as if Delta_1 were his guess.  True if Alice accepts."""
    chooser, holder = _pair()
    count, kappa = 64, 112
    total = count + check.extra_ots(kappa)
    nonce = secrets.token_bytes(32)
    columns, choice, sums = _bob_state(chooser, nonce, total)
    rows = [(u ^ choice) for u in sums[1:]]
    rows[0] = rows[0].copy()
    rows[0][0] ^= 1  # OT 0: Alice adds Delta_1 to its row in block 1's columns
    body = b"".join(r.tobytes() for r in rows)
    chi = check.challenges(nonce, body, total, kappa)
    x = check.fold_choices(choice, chi)
    t = check.fold_rows(columns, chi, kappa)
    k0 = chooser.blocks[0]
    delta_1 = holder.delta[1] if guess_right else holder.delta[1] ^ 1
    embedded = delta_1 << k0  # block 1's bits sit after block 0's in the columns
    chi_0 = int(chi[0][0]) | int(chi[0][1]) << 64
    t ^= check.field(kappa).mul(chi_0, embedded)  # what Alice's extra term will be if right
    gf = check.field(kappa)
    reply = x.to_bytes(gf.size, "big") + t.to_bytes(gf.size, "big")
    try:
        holder_extend(holder, nonce, count, body + reply)
    except ConsistencyError:
        return False
    return True


def test_a_selective_failure_passes_only_with_every_bit_of_the_block_guessed() -> None:
    """The deviation of the KOS analysis: it passes if and only if Bob knew Delta_1 (12
    bits).  A wrong guess -- here one bit off -- is caught, and the companion then drops
    the setup (tests/companion/attacks/test_deviating_peer.py)."""
    assert _selective_failure(guess_right=True)
    assert not _selective_failure(guess_right=False)


def test_a_corrupt_setup_never_yields_inconsistent_keys() -> None:
    """Bob corrupts one GGM correction of the setup (Alice's leaves then depend on one bit of
    her Delta).  Whatever that bit, either the check refuses the run or every key Alice gets
    matches Bob's: no run goes on with keys whose consistency depends on her Delta."""
    refused = accepted = 0
    for _ in range(24):
        start = HolderSetupStart()
        chooser, reply = chooser_setup(start.message(), start.blocks)
        corrupt = bytearray(reply)
        corrupt[32 + 16 * secrets.randbelow(4)] ^= 0x01  # a level pad of the first tree
        holder = start.finish(bytes(corrupt))
        nonce = secrets.token_bytes(32)
        message, bob = chooser_extend(chooser, nonce, 32)
        try:
            alice = holder_extend(holder, nonce, 32, message)
        except ConsistencyError:
            refused += 1
            continue
        accepted += 1
        for c, key, a0, a1 in zip(bob.choices, bob.keys, alice.keys0, alice.keys1, strict=True):
            assert key == (a0, a1)[c]
    # about half each (it depends on one bit of Delta); both at least once but with
    # probability 2^-23
    assert refused and accepted


def test_a_choice_changed_in_every_block_but_the_first_is_caught() -> None:
    """Bob flips OT 0 in every correction row and answers the check for the flipped choice
    bit: blocks 1.. now agree on c_0 xor 1, block 0 (whose u_0 *is* c) does not, so Alice's
    row carries Delta_0 and the check fails unless he guessed Delta_0 (12 bits)."""
    chooser, holder = _pair()
    count, kappa = 64, 112
    total = count + check.extra_ots(kappa)
    nonce = secrets.token_bytes(32)
    columns, choice, sums = _bob_state(chooser, nonce, total)
    rows = [(u ^ choice).copy() for u in sums[1:]]
    for row in rows:
        row[0] ^= 1
    body = b"".join(r.tobytes() for r in rows)
    flipped = choice.copy()
    flipped[0] ^= 1
    reply = check.respond(columns, flipped, nonce, body, total)
    with pytest.raises(ConsistencyError):
        holder_extend(holder, nonce, count, body + reply)
    honest = check.respond(columns, choice, nonce, body, total)  # nor with the old choice
    with pytest.raises(ConsistencyError):
        holder_extend(holder, nonce, count, body + honest)
