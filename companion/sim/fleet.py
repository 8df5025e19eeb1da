"""Certified identities for a replay: one key per operator, one key and certificate per drone,
each drone's trust store holding every operator the scenario trusts (simulation only: a real
fleet makes its keys with ``python -m companion keys``)."""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

from companion.auth.certificate import Certificate
from companion.auth.keys import SigningKey
from companion.auth.session import Identity
from companion.auth.trust import Operator, TrustStore, UnknownPeers
from companion.settings import Credentials

VALID_S = 14 * 86400  # long enough for the slowest replay's simulated hours


def make_fleet(
    drones: Iterable[tuple[int, str]],
    state_root: Path,
    *,
    untrusted: Iterable[str] = (),
    unknown: UnknownPeers = UnknownPeers.IGNORE,
    paper_keys: bool = False,
) -> dict[int, Credentials]:
    """Credentials per drone id from (id, operator name) pairs.  Every drone trusts every
    operator not in ``untrusted``; a drone of an untrusted operator trusts its own operator
    too (an intruder that tries to deconflict with a fleet that does not know it).
    ``paper_keys``: every trusted operator is trusted with paper-suite keys too."""
    drones = list(drones)
    operators = {name: SigningKey.generate() for name in sorted({op for _, op in drones})}
    excluded = set(untrusted)
    start = int(time.time()) - 300
    fleet: dict[int, Credentials] = {}
    for node, operator in drones:
        key = SigningKey.generate()
        cert = Certificate.issue(operators[operator], key.public, node, start, start + VALID_S)
        trusted = [
            Operator(name, op.public, paper_keys=paper_keys)
            for name, op in operators.items()
            if name not in excluded or name == operator
        ]
        fleet[node] = Credentials(
            Identity(key, cert), TrustStore(trusted, unknown), state_root / f"drone{node}"
        )
    return fleet
