"""``make demo`` for now: the cryptographic core end to end, on both bit back-ends.

Bob generates his keys; Alice compares encrypted values she cannot read, the XOR-shared results
are combined with an AND gate, and only the final bits are opened to Alice.  Every message goes
through its byte encoding; sizes and CPU times are printed as measured.
"""

from __future__ import annotations

import time

from .comparison import ComparisonAlice, ComparisonBob
from .dgk import DGKPrivateKey, DGKPublicKey
from .ecelgamal import ECPrivateKey, ECPublicKey
from .encoding import Reader
from .gadgets import AND, GateAlice, GateBob, OpenedShares
from .loopback import Transcript, run_comparison, run_gates
from .paillier import PaillierPrivateKey, PaillierPublicKey
from .zerotest import C, ZeroTestPrivateKey, ZeroTestPublicKey

L = 42
KAPPA = 40
# Alice asks, for each pair (x, y) of Bob-encrypted values: is lo <= x and x <= hi?
CASES = [(-5, -10, 10), (10, -10, 10), (11, -10, 10), (-11, -10, 10), (0, 0, 0), (2**40, 0, 2**41)]


def run_demo() -> int:
    print("Generating Bob's keys (Paillier-2048, DGK-2048 t=224, secp256k1)...", flush=True)
    start = time.process_time()
    paillier = PaillierPrivateKey.generate()
    dgk = DGKPrivateKey.generate()
    ecsk = ECPrivateKey.generate()
    print(f"  done in {time.process_time() - start:.2f} s CPU")
    alice_paillier = PaillierPublicKey.from_bytes(paillier.public_key.to_bytes())
    failures = _demo_backend(
        "compact (EC-ElGamal)",
        paillier,
        alice_paillier,
        ecsk,
        ECPublicKey.from_bytes(ecsk.public_key.to_bytes()),
    )
    failures += _demo_backend(
        "paper (DGK)",
        paillier,
        alice_paillier,
        dgk,
        DGKPublicKey.from_bytes(dgk.public_key.to_bytes()),
    )
    print("\nAll results correct." if not failures else f"\n{failures} WRONG results.")
    return 0 if not failures else 1


def _demo_backend(
    name: str,
    paillier: PaillierPrivateKey,
    alice_paillier: PaillierPublicKey,
    bits_sk: ZeroTestPrivateKey[C],
    bits_pub: ZeroTestPublicKey[C],
) -> int:
    """Range checks lo <= x <= hi on Bob-encrypted x; returns the number of wrong answers."""
    transcript = Transcript()
    # Bob's values reach Alice encrypted; she forms x - lo and hi - x homomorphically.
    enc_x = [
        alice_paillier.ciphertext_from_bytes(paillier.public_key.encrypt(x).to_bytes())
        for x, _, _ in CASES
    ]
    zero = alice_paillier.encrypt(0)
    diffs = [c - lo for c, (_, lo, _) in zip(enc_x, CASES, strict=True)]
    diffs += [zero + hi - c for c, (_, _, hi) in zip(enc_x, CASES, strict=True)]
    alice = ComparisonAlice(alice_paillier, bits_pub, L, KAPPA, diffs)
    bob = ComparisonBob(paillier, bits_sk, L, KAPPA, len(diffs))
    run_comparison(alice, bob, paillier.public_key, transcript)
    k = len(CASES)
    a, b = alice.shares, bob.shares
    gate_a = GateAlice(bits_pub, list(zip(a[:k], a[k:], strict=True)), [AND] * k)
    gate_b = GateBob(bits_sk, list(zip(b[:k], b[k:], strict=True)))
    a_in, b_in, _ = run_gates(gate_a, gate_b, transcript)
    opened = transcript.send("open", OpenedShares.from_shares(b_in).to_bytes(), from_alice=False)
    result = OpenedShares.read(Reader(opened), k).open(a_in)
    print(f"\n{name}: {len(diffs)} comparisons + {k} AND gates, one batch each")
    failures = 0
    for (x, lo, hi), bit in zip(CASES, result, strict=True):
        expected = int(lo <= x <= hi)
        failures += bit != expected
        mark = "ok" if bit == expected else "WRONG"
        print(f"  is {lo} <= x <= {hi}?  Alice learns {bool(bit)!s:5}  [{mark}]")
    print(
        f"  wire: {transcript.bytes_alice_to_bob} B Alice->Bob, "
        f"{transcript.bytes_bob_to_alice} B Bob->Alice in {transcript.messages} messages"
    )
    print(
        f"  CPU: Alice {transcript.cpu_alice * 1e3:.0f} ms, Bob {transcript.cpu_bob * 1e3:.0f} ms"
    )
    return failures
