"""Benchmarks of the cryptographic core: ``python -m protocol bench crypto [--json]``.

CPU time is ``time.process_time`` (this process only), reported as medians.  Bytes are the
lengths of the real serialised messages (:mod:`protocol.loopback`), never object sizes.  Alice
always works with public keys decoded from Bob's bytes, so her noise is computed the public (slow)
way, as on a real drone.  Both suites' comparisons run through the same sub-machines the path
protocol ships (:class:`~protocol.paper.comparison.ComparisonAlice` for the paper suite;
:mod:`protocol.compact.millionaire` and :mod:`protocol.compact.gmw` on :mod:`protocol.ot` for the
compact one).
"""

from __future__ import annotations

import secrets
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

from protocol.compact.millionaire import DEFAULT_DIGIT_BITS, Shape
from protocol.ot.extension import chooser_extend, holder_extend
from protocol.ot.setup import DEFAULT_BLOCKS, ChooserSetup, HolderSetup, describe
from protocol.paper.comparison import ComparisonAlice, ComparisonBob, pack_differences
from protocol.primitives import secp256k1 as ec
from protocol.primitives.dgk import DGKPrivateKey, DGKPublicKey
from protocol.primitives.paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from protocol.primitives.params import SecurityParameters
from protocol.tools.loopback import Transcript, run_comparison, run_millionaires, run_ot_setup

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


def primitive_rows(paillier: PaillierPrivateKey, dgk: DGKPrivateKey, repeat: int) -> list[Row]:
    """Median CPU time of each primitive, public (Alice) and key-holder (Bob) paths."""
    pub = PaillierPublicKey.from_bytes(paillier.public_key.to_bytes())
    dpub = DGKPublicKey.from_bytes(dgk.public_key.to_bytes())
    c = pub.encrypt(secrets.randbits(64))
    d = pub.encrypt(secrets.randbits(64))
    k40 = secrets.randbits(40)
    dc = dpub.encrypt(1)

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
        {
            "primitive": "secp256k1 variable-base multiply",
            "s": median_cpu(lambda: ec.mul(ec.base_mul(7), secrets.randbits(256)), repeat * 4),
        },
    ]
    return rows


def ot_rows(repeat: int) -> tuple[list[Row], ChooserSetup, HolderSetup]:
    """The one-time OT setup and the per-run extension: CPU per side and bytes."""
    setup_runs = [run_ot_setup() for _ in range(max(3, repeat // 3))]
    chooser, setup, _ = setup_runs[-1]
    rows: list[Row] = [
        {
            "what": f"OT setup ({sum(setup.blocks)} base OTs + {len(setup.blocks)} punctured "
            "trees), once per pair of drones",
            "cpu_alice_ms": 1e3 * statistics.median(r[2].cpu_alice for r in setup_runs),
            "cpu_bob_ms": 1e3 * statistics.median(r[2].cpu_bob for r in setup_runs),
            "bytes_alice_to_bob": setup_runs[0][2].bytes_alice_to_bob,
            "bytes_bob_to_alice": setup_runs[0][2].bytes_bob_to_alice,
        }
    ]
    for count in (1000, 10000):
        runs = []
        for _ in range(max(3, repeat // 3)):
            nonce = secrets.token_bytes(32)
            start = time.process_time()
            message, _ = chooser_extend(chooser, nonce, count)
            mid = time.process_time()
            holder_extend(setup, nonce, count, message)
            end = time.process_time()
            runs.append((end - mid, mid - start, len(message)))
        rows.append(
            {
                "what": f"OT extension, {count} random OTs in one run",
                "cpu_alice_ms": 1e3 * statistics.median(r[0] for r in runs),
                "cpu_bob_ms": 1e3 * statistics.median(r[1] for r in runs),
                "bytes_alice_to_bob": 0,
                "bytes_bob_to_alice": runs[0][2],
            }
        )
    return rows, chooser, setup


def _per(transcripts: list[Transcript], count: int, suite: str, l: int, extra: str) -> Row:
    last = transcripts[-1]
    cpu_a = statistics.median(t.cpu_alice for t in transcripts)
    cpu_b = statistics.median(t.cpu_bob for t in transcripts)
    return {
        "suite": suite,
        "l": l,
        "count": count,
        "detail": extra,
        "cpu_alice_ms": 1000 * cpu_a / count,
        "cpu_bob_ms": 1000 * cpu_b / count,
        "cpu_total_ms": 1000 * (cpu_a + cpu_b) / count,
        "bytes_alice_to_bob": last.bytes_alice_to_bob / count,
        "bytes_bob_to_alice": last.bytes_bob_to_alice / count,
        "bytes_total": (last.bytes_alice_to_bob + last.bytes_bob_to_alice) / count,
        "messages": last.messages,
    }


def paper_comparison_row(
    paillier: PaillierPrivateKey, dgk: DGKPrivateKey, l: int, kappa: int, count: int, repeat: int
) -> Row:
    """Veugen on DGK: ``count`` comparisons of [x >= y] in one batch, fresh public keys."""
    runs = []
    for _ in range(repeat):
        pub = PaillierPublicKey.from_bytes(paillier.public_key.to_bytes())
        dpub = DGKPublicKey.from_bytes(dgk.public_key.to_bytes())
        lo, hi = -(2 ** (l - 1)), 2 ** (l - 1)
        diffs: list[PaillierCiphertext] = [
            pub.ciphertext_from_bytes(
                (
                    paillier.public_key.encrypt(lo + secrets.randbelow(hi - lo))
                    - paillier.public_key.encrypt(lo + secrets.randbelow(hi - lo))
                )
                .rerandomize()
                .to_bytes()
            )
            for _ in range(count)
        ]
        packed = pack_differences(pub, diffs, l, kappa)
        alice = ComparisonAlice(pub, dpub, l, kappa, packed, [[0]] * count)
        bob = ComparisonBob(
            paillier, dgk, l, kappa, [len(p.constants) for p in packed], [1] * count
        )
        runs.append(run_comparison(alice, bob))
    return _per(runs, count, "paper", l, "Paillier + DGK, Veugen (XOR-shared result)")


def compact_comparison_row(
    chooser: ChooserSetup, holder: HolderSetup, l: int, count: int, repeat: int
) -> Row:
    """OT millionaires: ``count`` comparisons of Bob's l-bit value with Alice's, one run
    (extension, digits, tables, AND tree; the result opened to Alice at the end)."""
    runs = []
    shape = Shape.of(l, DEFAULT_DIGIT_BITS, [1] * count)
    for _ in range(repeat):
        bob = [secrets.randbits(l) for _ in range(count)]
        alice = [[secrets.randbits(l)] for _ in range(count)]
        _, transcript = run_millionaires(chooser, holder, shape, bob, alice)
        runs.append(transcript)
    return _per(
        runs,
        count,
        "compact",
        l,
        f"OT millionaires, {DEFAULT_DIGIT_BITS}-bit digits (setup cached)",
    )


def bench_crypto(repeat: int = 15, progress: bool = True) -> dict[str, Any]:
    """Everything ``bench crypto`` reports."""
    params = SecurityParameters()
    say = _progress if progress else (lambda _m: None)
    say("generating keys")
    paillier = PaillierPrivateKey.generate(params.paillier_bits)
    dgk = DGKPrivateKey.generate(params.dgk_bits, params.dgk_t)
    say("timing primitives")
    primitives = primitive_rows(paillier, dgk, repeat)
    say("OT setup and extension")
    ot, chooser, holder = ot_rows(repeat)
    comparisons: list[Row] = []
    for l in (20, 42):
        for count in (1, 24):
            runs = repeat if count == 1 else max(3, repeat // 5)
            say(f"comparison l={l} batch={count}")
            comparisons.append(paper_comparison_row(paillier, dgk, l, params.kappa, count, runs))
            comparisons.append(compact_comparison_row(chooser, holder, l, count, runs))
    return {
        "params": {
            "paillier_bits": params.paillier_bits,
            "dgk_bits": params.dgk_bits,
            "dgk_t": dgk.public_key.t,
            "dgk_u": dgk.public_key.u,
            "kappa": params.kappa,
            "curve": "secp256k1",
            "ot": describe(DEFAULT_BLOCKS),
            "repeat": repeat,
        },
        "primitives": primitives,
        "ot": ot,
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
        "| OT | Alice ms | Bob ms | A->B B | B->A B |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in result["ot"]:
        lines.append(
            f"| {r['what']} | {r['cpu_alice_ms']:.1f} | {r['cpu_bob_ms']:.1f} "
            f"| {r['bytes_alice_to_bob']} | {r['bytes_bob_to_alice']} |"
        )
    lines += [
        "",
        "| suite | l | batch | Alice ms | Bob ms | total ms | A->B B | B->A B | total B | msgs |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["comparisons"]:
        lines.append(
            f"| {r['suite']} | {r['l']} | {r['count']} | {r['cpu_alice_ms']:.2f} "
            f"| {r['cpu_bob_ms']:.2f} | {r['cpu_total_ms']:.2f} | {r['bytes_alice_to_bob']:.0f} "
            f"| {r['bytes_bob_to_alice']:.0f} | {r['bytes_total']:.0f} | {r['messages']} |"
        )
    lines.append("")
    lines.append(
        "Per-comparison figures (a batch shares its messages).  Paper: Paillier + DGK (Veugen), "
        "XOR-shared result.  Compact: OT extension + 4-bit-digit millionaires + AND tree on "
        "Beaver triples, result opened to Alice (1 bit); its one-time OT setup is in the OT "
        "table, not in these rows."
    )
    return "\n".join(lines)
