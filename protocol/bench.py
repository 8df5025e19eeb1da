"""Benchmarks of the cryptographic core: ``python -m protocol bench crypto [--json]``.

CPU time is ``time.process_time`` (this process only), reported as medians.  Bytes are the
lengths of the real serialised messages (:mod:`protocol.loopback`), never object sizes.  Alice
always works with public keys decoded from Bob's bytes, so her noise is computed the public (slow)
way, as on a real drone.
"""

from __future__ import annotations

import secrets
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

from . import secp256k1 as ec
from .comparison import ComparisonAlice, ComparisonBob, packed_count
from .dgk import DGKPrivateKey, DGKPublicKey
from .ecelgamal import ECPrivateKey, ECPublicKey
from .loopback import Transcript, run_comparison
from .paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from .params import SecurityParameters
from .zerotest import C, ZeroTestPrivateKey, ZeroTestPublicKey

Row = dict[str, Any]


def median_cpu(action: Callable[[], object], repeat: int) -> float:
    """Median CPU seconds of ``action`` over ``repeat`` runs."""
    samples = []
    for _ in range(repeat):
        start = time.process_time()
        action()
        samples.append(time.process_time() - start)
    return statistics.median(samples)


def _progress(message: str) -> None:
    print(f"  ... {message}", file=sys.stderr, flush=True)


def primitive_rows(
    paillier: PaillierPrivateKey, dgk: DGKPrivateKey, ecsk: ECPrivateKey, repeat: int
) -> list[Row]:
    """Median CPU time of each primitive, public (Alice) and key-holder (Bob) paths."""
    pub = PaillierPublicKey.from_bytes(paillier.public_key.to_bytes())
    dpub = DGKPublicKey.from_bytes(dgk.public_key.to_bytes())
    epub = ECPublicKey.from_bytes(ecsk.public_key.to_bytes())
    c = pub.encrypt(secrets.randbits(64))
    d = pub.encrypt(secrets.randbits(64))
    k40 = secrets.randbits(40)
    dc = dpub.encrypt(1)
    ecc = epub.encrypt(1)

    def pooled_encrypt() -> PaillierCiphertext:
        pub.noise_pool.fill(1)
        start = time.process_time()
        result = pub.encrypt(7)
        pooled_times.append(time.process_time() - start)
        return result

    pooled_times: list[float] = []
    for _ in range(repeat):
        pooled_encrypt()
    rows: list[Row] = [
        {
            "primitive": "paillier keygen (2048)",
            "s": median_cpu(lambda: PaillierPrivateKey.generate(), max(3, repeat // 4)),
        },
        {
            "primitive": "paillier encrypt, public fresh noise",
            "s": median_cpu(lambda: pub.encrypt(5), repeat),
        },
        {"primitive": "paillier encrypt, precomputed noise", "s": statistics.median(pooled_times)},
        {
            "primitive": "paillier noise r^n, key holder CRT",
            "s": median_cpu(paillier.public_key.noise_pool.take, repeat),
        },
        {
            "primitive": "paillier decrypt (CRT)",
            "s": median_cpu(lambda: paillier.decrypt(c), repeat),
        },
        {"primitive": "paillier add", "s": median_cpu(lambda: c + d, repeat * 10)},
        {
            "primitive": "paillier multiply by 40-bit scalar",
            "s": median_cpu(lambda: c * k40, repeat * 4),
        },
        {
            "primitive": "dgk keygen (2048, t=224)",
            "s": median_cpu(lambda: DGKPrivateKey.generate(), max(3, repeat // 4)),
        },
        {"primitive": "dgk encrypt, public", "s": median_cpu(lambda: dpub.encrypt(1), repeat)},
        {
            "primitive": "dgk encrypt, key holder CRT",
            "s": median_cpu(lambda: dgk.public_key.encrypt(1), repeat),
        },
        {
            "primitive": "dgk blind + rerandomise, public",
            "s": median_cpu(lambda: dpub.blind(dc), repeat),
        },
        {"primitive": "dgk zero test", "s": median_cpu(lambda: dgk.is_zero(dc), repeat * 4)},
        {"primitive": "ec keygen", "s": median_cpu(ECPrivateKey.generate, repeat)},
        {"primitive": "ec encrypt, public", "s": median_cpu(lambda: epub.encrypt(1), repeat * 4)},
        {
            "primitive": "ec encrypt, key holder batch (per value)",
            "s": median_cpu(lambda: ecsk.encrypt_batch([1] * 32), repeat) / 32,
        },
        {
            "primitive": "ec blind + rerandomise",
            "s": median_cpu(lambda: epub.blind(ecc), repeat * 4),
        },
        {"primitive": "ec zero test", "s": median_cpu(lambda: ecsk.is_zero(ecc), repeat * 4)},
        {
            "primitive": "secp256k1 variable-base multiply",
            "s": median_cpu(lambda: ec.mul(epub.h, secrets.randbits(256)), repeat * 4),
        },
    ]
    return rows


def comparison_row(
    paillier: PaillierPrivateKey,
    bits_sk: DGKPrivateKey | ECPrivateKey,
    l: int,
    kappa: int,
    count: int,
    repeat: int,
    precomputed: bool,
) -> Row:
    """Median CPU per party and wire bytes of ``count`` comparisons in one batch."""
    runs = []
    for _ in range(repeat):
        if isinstance(bits_sk, DGKPrivateKey):
            dpub = DGKPublicKey.from_bytes(bits_sk.public_key.to_bytes())
            runs.append(_one_comparison(paillier, bits_sk, dpub, l, kappa, count, precomputed))
        else:
            epub = ECPublicKey.from_bytes(bits_sk.public_key.to_bytes())
            runs.append(_one_comparison(paillier, bits_sk, epub, l, kappa, count, precomputed))
    last = runs[-1][0]
    cpu_a = statistics.median(t.cpu_alice for t, _ in runs)
    cpu_b = statistics.median(t.cpu_bob for t, _ in runs)
    cpu_pre = statistics.median(pre for _, pre in runs)
    return {
        "backend": "dgk" if isinstance(bits_sk, DGKPrivateKey) else "ec",
        "l": l,
        "count": count,
        "noise": "precomputed" if precomputed else "inline",
        "cpu_alice_ms": 1000 * cpu_a / count,
        "cpu_bob_ms": 1000 * cpu_b / count,
        "cpu_total_ms": 1000 * (cpu_a + cpu_b) / count,
        "precompute_ms": 1000 * cpu_pre / count,
        "bytes_alice_to_bob": last.bytes_alice_to_bob / count,
        "bytes_bob_to_alice": last.bytes_bob_to_alice / count,
        "bytes_total": (last.bytes_alice_to_bob + last.bytes_bob_to_alice) / count,
        "messages": last.messages,
        "round_trips": last.round_trips,
    }


def _one_comparison(
    paillier: PaillierPrivateKey,
    bits_sk: ZeroTestPrivateKey[C],
    bits_pub: ZeroTestPublicKey[C],
    l: int,
    kappa: int,
    count: int,
    precomputed: bool,
) -> tuple[Transcript, float]:
    """One batch on fresh public-key copies; returns the transcript and precompute CPU."""
    pub = PaillierPublicKey.from_bytes(paillier.public_key.to_bytes())
    lo, hi = -(2 ** (l - 1)), 2 ** (l - 1)
    diffs = [
        paillier.public_key.encrypt(lo + secrets.randbelow(hi - lo))
        - paillier.public_key.encrypt(lo + secrets.randbelow(hi - lo))
        for _ in range(count)
    ]
    inputs = [pub.ciphertext_from_bytes(x.rerandomize().to_bytes()) for x in diffs]
    pre = 0.0
    if precomputed:
        start = time.process_time()
        pub.noise_pool.fill(packed_count(pub, l, kappa, count))
        if isinstance(bits_pub, DGKPublicKey):
            bits_pub.noise_pool.fill(count * (l + 1))
        pre = time.process_time() - start
    alice = ComparisonAlice(pub, bits_pub, l, kappa, inputs)
    bob = ComparisonBob(paillier, bits_sk, l, kappa, count)
    return run_comparison(alice, bob, paillier.public_key), pre


def bench_crypto(repeat: int = 15, progress: bool = True) -> dict[str, Any]:
    """Everything ``bench crypto`` reports."""
    params = SecurityParameters()
    say = _progress if progress else (lambda _m: None)
    say("generating keys")
    paillier = PaillierPrivateKey.generate(params.paillier_bits)
    dgk = DGKPrivateKey.generate(params.dgk_bits, params.dgk_t)
    ecsk = ECPrivateKey.generate()
    say("timing primitives")
    primitives = primitive_rows(paillier, dgk, ecsk, repeat)
    comparisons: list[Row] = []
    for bits_sk in (ecsk, dgk):
        for l in (20, 42):
            for count, precomputed in ((1, False), (1, True), (24, False)):
                name = "dgk" if bits_sk is dgk else "ec"
                say(
                    f"comparison {name} l={l} batch={count} noise="
                    f"{'precomputed' if precomputed else 'inline'}"
                )
                comparisons.append(
                    comparison_row(
                        paillier,
                        bits_sk,
                        l,
                        params.kappa,
                        count,
                        repeat if count == 1 else max(3, repeat // 5),
                        precomputed,
                    )
                )
    return {
        "params": {
            "paillier_bits": params.paillier_bits,
            "dgk_bits": params.dgk_bits,
            "dgk_t": dgk.public_key.t,
            "dgk_u": dgk.public_key.u,
            "kappa": params.kappa,
            "curve": "secp256k1",
            "repeat": repeat,
        },
        "primitives": primitives,
        "comparisons": comparisons,
    }


def format_crypto(result: dict[str, Any]) -> str:
    """Plain-text (Markdown) tables of :func:`bench_crypto`'s result."""
    p = result["params"]
    lines = [
        f"Parameters: Paillier n = {p['paillier_bits']} bits, DGK n = {p['dgk_bits']} bits, "
        f"t = {p['dgk_t']}, u = {p['dgk_u']}, kappa = {p['kappa']}, curve {p['curve']}; "
        f"medians of {p['repeat']} runs (CPU time of this process).",
        "",
        "| primitive | median |",
        "|---|---:|",
    ]
    for row in result["primitives"]:
        s = row["s"]
        shown = f"{s * 1e3:.2f} ms" if s >= 1e-3 else f"{s * 1e6:.1f} us"
        lines.append(f"| {row['primitive']} | {shown} |")
    lines += [
        "",
        "| back-end | l | batch | noise | Alice ms | Bob ms | total ms | A->B B | B->A B "
        "| total B | msgs |",
        "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["comparisons"]:
        noise = r["noise"] + (
            f" (+{r['precompute_ms']:.1f} ms before)" if r["precompute_ms"] else ""
        )
        lines.append(
            f"| {r['backend']} | {r['l']} | {r['count']} | {noise} | {r['cpu_alice_ms']:.1f} "
            f"| {r['cpu_bob_ms']:.1f} | {r['cpu_total_ms']:.1f} | {r['bytes_alice_to_bob']:.0f} "
            f"| {r['bytes_bob_to_alice']:.0f} | {r['bytes_total']:.0f} | {r['messages']} |"
        )
    lines.append("")
    lines.append("Per-comparison figures; a batch of 24 shares its messages (3 in all).")
    return "\n".join(lines)
