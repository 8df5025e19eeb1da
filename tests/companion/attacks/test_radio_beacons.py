"""The attacker on the radio against beacons and identities, with the real link, runtime and
authentication (virtual time): replayed beacons, spoofed node ids and fingerprints, drones of
untrusted operators, paper-suite keys that do not match the beacons.  Each test is one attack
of ``docs/security.md`` and shows it fails."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from companion.auth.certificate import Certificate
from companion.auth.session import Initiator, Route
from companion.auth.trust import UnknownPeers
from companion.neighbours.beacon import CertBeacon, decode_beacon
from companion.radio.frames import BROADCAST, Frame, FrameType
from companion.sim.virtual_time import run_simulated
from protocol.geo.grid import GridSpec
from protocol.intersection import Alice
from tests.companion.attacks.harness import World, aborts_are_codes, world

pytestmark = pytest.mark.attack


def run(main: Any) -> Any:
    return run_simulated(main)


def position_beacons(w: World, node: int) -> list[Frame]:
    """The position beacons ``node`` has sent (a certificate played again is no news)."""
    return [
        f for _, f in w.sniffer.frames
        if f.type is FrameType.BEACON and f.src == node
        and not isinstance(decode_beacon(f.payload), CertBeacon)
    ]  # fmt: skip


def test_replayed_beacons_are_dropped(tmp_path: Path) -> None:
    """Every position beacon drone 2 sent, played again later: drone 1 drops each one and its
    view of drone 2 does not move.  (A certificate played again is no news: it is public.)"""

    async def main() -> tuple[World, int, int]:
        w = await world(tmp_path)
        await w.clock.sleep(120)
        await w.drones[2].stop()  # silent now: whatever drone 1 hears of "2" is the attacker
        await w.clock.sleep(2)  # a frame still on its way when drone 2 stopped has landed
        recorded = position_beacons(w, 2)
        peer = w.drones[1].neighbourhood.peers[2]
        heard, before = peer.heard_at, sum(w.drones[1].neighbourhood.rejected.values())
        for frame in recorded:
            await w.inject(frame.encode())
        await w.clock.sleep(0.5)
        drops = sum(w.drones[1].neighbourhood.rejected.values()) - before
        assert peer.heard_at == heard  # nothing replayed moved the peer
        await w.stop()
        return w, len(recorded), drops

    w, recorded, drops = run(main())
    assert recorded >= 3 and drops == recorded
    assert any("replay" in reason for reason in w.drones[1].neighbourhood.rejected)


@pytest.mark.parametrize("later_s", [65_536, 65_536 * 7 + 12])
def test_beacons_recorded_hours_ago_are_never_fresh_again(tmp_path: Path, later_s: int) -> None:
    """Beacons drone 2 sent, played again 2^16 s (18 h 12 min) later -- or seven times that,
    a little off: with the time cut to its low 16 bits they read as "now" and swapped in the
    recorded keys.  With whole times each one is stale: dropped for its time, the peer does
    not move."""

    async def main() -> tuple[World, int, dict[str, int]]:
        w = await world(tmp_path)
        await w.clock.sleep(120)
        await w.drones[2].stop()
        await w.clock.sleep(2)
        recorded = position_beacons(w, 2)
        peer = w.drones[1].neighbourhood.peers[2]
        heard, rejected = peer.heard_at, dict(w.drones[1].neighbourhood.rejected)
        w.clock.shift_wall(later_s)  # the hours pass
        for frame in recorded:
            await w.inject(frame.encode())
        await w.clock.sleep(0.5)
        assert peer.heard_at == heard  # nothing replayed moved the peer
        new = {k: v - rejected.get(k, 0) for k, v in w.drones[1].neighbourhood.rejected.items()}
        await w.stop()
        return w, len(recorded), {k: v for k, v in new.items() if v}

    _, recorded, drops = run(main())
    assert recorded >= 3 and sum(drops.values()) == recorded
    assert all(reason.startswith("time") and "s off" in reason for reason in drops), drops


def test_spoofed_node_ids_and_fingerprints_are_ignored(tmp_path: Path) -> None:
    """An attacker without a trusted certificate speaks as drone 1: drone 1's node id on its
    frames, a certificate for node 1 from an operator of its own, beacons, and run requests
    naming drone 1's fingerprint; then as fifty made-up node ids.  Drone 2 answers none,
    spends none of drone 1's budget, and still deconflicts with the real drone 1."""

    async def main() -> tuple[World, dict[str, int]]:
        w = await world(tmp_path, extra={9: "mallory"}, untrusted=("mallory",))
        mallory = w.credentials[9].identity
        real = w.credentials[1].identity
        fake_cert = Certificate.issue(mallory.key, mallory.key.public, 1, 0, 2**32 - 1)
        cert_frame = Frame(FrameType.BEACON, 1, BROADCAST, 0, 0, 0, 1,
                           CertBeacon(fake_cert).encode())  # fmt: skip
        await w.inject(cert_frame.encode())
        for k in range(5):  # requests naming drone 1, signed by mallory
            session = 30_000 + k
            alice = Alice(((0, 0), (1, 1)), GridSpec.geo(473_990_000, 85_450_000))
            initiator = Initiator(
                mallory, w.credentials[2].identity.cert, Route(1, 2, session), w.clock.wall()
            )
            msg1 = initiator.first(alice.start())
            msg1 = msg1[:1] + real.fingerprint + msg1[9:]  # claims drone 1's fingerprint
            await w.inject_message(1, 2, session, msg1)
            await w.clock.sleep(3)
        for node in range(100, 150):  # made-up addresses, each with a certificate of its own
            cert = Certificate.issue(mallory.key, mallory.key.public, node, 0, 2**32 - 1)
            frame = Frame(FrameType.BEACON, node, BROADCAST, 0, 0, 0, 1, CertBeacon(cert).encode())
            await w.inject(frame.encode())
        await w.clock.sleep(600)  # (the attacker's frames jam the channel meanwhile)
        bob = w.drones[2]
        counts = {
            "drone1": bob.store.count_runs(0, "bob", drone=real.fingerprint),
            "all": bob.store.count_runs(0, "bob"),
        }
        await w.stop()
        return w, counts

    w, counts = run(main())
    # the real drone 1's runs that drone 2 completed (a run the attacker's frames jammed
    # before its end taught nothing and was given back)
    results = len(w.events(1, "result"))
    assert counts == {"drone1": results, "all": results}
    assert w.events(1, "result") and w.autopilots[1].uploads  # the real drone 1 got through
    assert set(w.drones[2].neighbourhood.peers) == {1}
    assert not any("answered" == e.kind and e.detail.get("peer") != 1 for e in w.drones[2].events)
    aborts_are_codes(w)


def test_a_drone_of_an_untrusted_operator_is_ignored(tmp_path: Path) -> None:
    """Drone 3 flies for an operator neither drone 1 nor drone 2 trusts: they never take it
    for a peer, answer none of its requests, spend no budget on it, and say so once (policy
    "alert": also where it is, at most once a minute)."""

    async def main() -> tuple[World, dict[int, int]]:
        w = await world(
            tmp_path,
            missions={1: "delivery_east.plan", 2: "inspection_north.plan", 3: "mast_east.plan"},
            operators={3: "rogue"},
            untrusted=("rogue",),
            unknown=UnknownPeers.ALERT,
        )
        await w.clock.sleep(400)
        rogue = w.credentials[3].identity.fingerprint
        spent = {n: w.drones[n].store.count_runs(0, "bob", drone=rogue) for n in (1, 2)}
        await w.stop()
        return w, spent

    w, spent = run(main())
    assert spent == {1: 0, 2: 0}
    for node in (1, 2):
        assert 3 not in w.drones[node].neighbourhood.peers
        assert len(w.events(node, "untrusted")) == 1
        intruder = w.events(node, "intruder")
        assert intruder and all(e["peer"] == 3 and "distance_m" in e for e in intruder)
    assert not w.events(3, "result")  # the intruder learnt nothing
    assert w.events(1, "result") and w.autopilots[1].uploads  # 1 and 2 deconflicted


def test_paper_suite_keys_must_match_the_beacons(tmp_path: Path) -> None:
    """Paper suite: Bob's Paillier and DGK keys travel in his first reply.  With the keys his
    signed beacons announce, the run gives a result; when his reply carries other keys than
    his beacons announced (here: the hash they announce made up), drone 1 refuses the run as
    unauthenticated and reports nothing."""
    from protocol.messages import Suite

    async def main(forge_keys: bool) -> World:
        w = await world(
            tmp_path / str(forge_keys), settings={"suite": Suite.PAPER}, paper_keys=True
        )
        if forge_keys:
            w.drones[2].sender.keys_hash = bytes(16)  # what its beacons will say from now on
        await w.clock.sleep(3600)
        await w.stop()
        return w

    honest = run(main(False))
    assert honest.events(1, "result") and honest.autopilots[1].uploads
    forged = run(main(True))
    assert not forged.events(1, "result") and not forged.autopilots[1].uploads
    assert any("do not match" in f.get("auth", "") for f in forged.events(1, "run_failed"))
