"""The trust store: the operators whose drones this companion deconflicts with.

A peer counts when its certificate (:mod:`.certificate`) is signed by an operator in the
store, is valid now and names the node it speaks from.  Everybody else -- a stranger on the
radio, a drone of an operator we have no agreement with, an expired certificate -- is
ignored (:class:`UnknownPeers` says whether the companion also reports it).  Each operator
carries its own limits: how many segments a run of its drones may have, how many runs per
hour its drones may ask of us together (``companion.runs.budget``).
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass

from companion.auth.certificate import Certificate
from companion.auth.keys import PublicKey
from companion.errors import CompanionError


class UnknownPeers(enum.Enum):
    """What to do with a drone that is not trusted: always ignored for deconfliction."""

    IGNORE = "ignore"  # logged once per drone
    ALERT = "alert"  # also recorded as an ``intruder`` event with its claimed position


class Untrusted(enum.Enum):
    UNKNOWN_OPERATOR = "operator not in the trust store"
    BAD_SIGNATURE = "certificate signature does not verify"
    NOT_YET_VALID = "certificate not valid yet"
    EXPIRED = "certificate expired"
    WRONG_NODE = "certificate names another node id"


class UntrustedPeer(CompanionError):
    """A certificate the store does not accept; ``reason`` says why."""

    def __init__(self, reason: Untrusted, cert: Certificate) -> None:
        super().__init__(f"drone {cert.fingerprint.hex()}: {reason.value}")
        self.reason = reason
        self.cert = cert


@dataclass(frozen=True, slots=True)
class Operator:
    name: str
    key: PublicKey
    max_segments: int = 256  # largest padded path a run with its drones may have
    max_runs_per_hour: int = 24  # runs its drones together may ask of us per hour
    # Answer bits its drones together may open per hour: a deviating operator's drones can
    # each ask bits of their choosing (docs/security.md, D6); this bounds them all together.
    max_answer_bits_per_hour: int = 1024
    # The paper suite's Paillier and DGK keys come without a proof that they are well formed
    # (docs/security.md, "A deviating peer"): we run it only with drones of operators we
    # trust to have checked their drones' keys.  The compact suite needs no such trust.
    paper_keys: bool = False

    def __post_init__(self) -> None:
        if not 1 <= self.max_segments <= 256:
            raise ValueError(f"operator {self.name}: max_segments 1..256")
        if self.max_runs_per_hour < 1:
            raise ValueError(f"operator {self.name}: max_runs_per_hour >= 1")
        if self.max_answer_bits_per_hour < 1:
            raise ValueError(f"operator {self.name}: max_answer_bits_per_hour >= 1")


class TrustStore:
    def __init__(
        self, operators: Iterable[Operator] = (), unknown: UnknownPeers = UnknownPeers.IGNORE
    ) -> None:
        self.operators = {op.key.fingerprint: op for op in operators}
        self.unknown = unknown

    def check(self, cert: Certificate, node: int, unix_s: float) -> Operator:
        """The operator vouching for ``cert`` heard from ``node`` at ``unix_s``, or
        :class:`UntrustedPeer`."""
        operator = self.operators.get(cert.operator)
        if operator is None:
            raise UntrustedPeer(Untrusted.UNKNOWN_OPERATOR, cert)
        if not cert.signed_by(operator.key):
            raise UntrustedPeer(Untrusted.BAD_SIGNATURE, cert)
        if unix_s < cert.not_before:
            raise UntrustedPeer(Untrusted.NOT_YET_VALID, cert)
        if unix_s > cert.not_after:
            raise UntrustedPeer(Untrusted.EXPIRED, cert)
        if cert.node != node:
            raise UntrustedPeer(Untrusted.WRONG_NODE, cert)
        return operator
