"""The probing budget: how many runs peers may ask of us (the paper's probing attack).

Alice learns one bit per segment per run; with many runs she could trace Bob's path.  The
budget counts the runs we answer (as Bob) over a sliding window, on disk
(:class:`StateStore`), per *certified* drone, per operator and in all -- never per node id or
anything else a peer only claims -- and every limit holds across restarts.  A run that ends
before Bob's first reply taught Alice nothing and is given back; from that reply on (it
shows his padded size n) it counts, and an outsider cannot make it end without an answer
(aborts carry the session's proof; a keyed run outlasts a jammer: :mod:`companion.runs.exchange`).
The runs we start (as Alice) are counted apart, per drone, and given back when they bring no
result, so that a fault cannot make us call a peer without end (failed runs are retried
after a pause).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from companion.errors import CompanionError
from companion.roles import Role
from companion.state import StateStore

ALICE, BOB = Role.ALICE, Role.BOB


# The work one run may ask of Bob: (Alice's padded segments m) x (Bob's padded size n, from
# his own remaining path: public in his beacons) x (bits of the grid's range).  Bytes, CPU
# and memory of a run grow with it (docs/benchmarks.md, "Bob's work per request"): at this
# bound a run is about 240 KB, Bob's largest message about 110 KB (the link takes 1 MiB), his
# CPU about 2.2 s and the process's peak memory about 200 MB (single runs, both parties in
# one process); the largest request the other limits admit (256 x 16 at 20 bits, 20 times
# this) cost Bob 28.9 s and 1.28 GB (quoted from issue 27).  An honest Alice cuts her runs
# to it (a full run goes in parts); a request above it is refused (SIZE) before any work.
MAX_RUN_WORK = 16 * 16 * 16


def run_work(m: int, n: int, grid_range: int) -> int:
    """What a run of m x n segments on a grid of ``grid_range`` cells asks of Bob."""
    return m * n * max(grid_range, 1).bit_length()


class Scope(enum.Enum):
    DRONE = "drone"
    OPERATOR = "operator"
    TOTAL = "total"
    DRONE_BITS = "drone answer-bit"  # what one drone may learn of us, whatever it computes
    OPERATOR_BITS = "operator answer-bit"  # what all the drones of one operator may learn


class BudgetExceeded(CompanionError):
    """No run now: ``scope`` says which limit is used up."""

    def __init__(self, scope: Scope, limit: int, window_s: float) -> None:
        unit = "bits" if scope in (Scope.DRONE_BITS, Scope.OPERATOR_BITS) else "runs"
        super().__init__(f"{scope.value} limit of {limit} {unit} per {window_s:.0f} s reached")
        self.scope = scope


@dataclass(frozen=True, slots=True)
class RunLimits:
    per_drone: int = 8  # an in-flight encounter takes a near and a full run
    total: int = 64  # all peers together
    window_s: float = 3600.0
    # Answer bits (Alice's padded segments m of each run) one drone may open per window: a
    # deviating Alice can make each of her m output bits a predicate of her choice
    # (docs/security.md, D6), so this, not the run count, bounds what she learns of us.
    bits_per_drone: int = 256

    def __post_init__(self) -> None:
        if min(self.per_drone, self.total, self.bits_per_drone) < 1 or self.window_s <= 0:
            raise ValueError("run limits must be positive")


class RunLedger:
    def __init__(self, store: StateStore, limits: RunLimits) -> None:
        self.store, self.limits = store, limits

    def admit(
        self,
        drone: bytes,
        operator: bytes,
        operator_limit: int,
        now: float,
        role: Role = BOB,
        bits: int = 0,
        operator_bits: int | None = None,
    ) -> int:
        """Count one more run in ``role`` with ``drone`` (of ``operator``, whose drones may
        ask ``operator_limit`` runs and open ``operator_bits`` answer bits per window
        together), one that opens ``bits`` answer bits to it; its ticket, for :meth:`refund`.
        Raise :class:`BudgetExceeded` instead if that is too many.  As Alice only the
        per-drone run limit applies."""
        since = now - self.limits.window_s
        count = self.store.count_runs
        checks = [(Scope.DRONE, self.limits.per_drone, count(since, role, drone=drone) + 1)]
        if role == BOB:
            checks += [
                (Scope.OPERATOR, operator_limit, count(since, role, operator=operator) + 1),
                (Scope.TOTAL, self.limits.total, count(since, role) + 1),
                (
                    Scope.DRONE_BITS,
                    self.limits.bits_per_drone,
                    count(since, role, drone=drone, bits=True) + bits,
                ),
            ]
            if operator_bits is not None:
                wanted = count(since, role, operator=operator, bits=True) + bits
                checks.append((Scope.OPERATOR_BITS, operator_bits, wanted))
        for scope, limit, wanted in checks:
            if wanted > limit:
                raise BudgetExceeded(scope, limit, self.limits.window_s)
        self.store.forget_runs(now - 2 * self.limits.window_s)
        return self.store.record_run(now, drone, operator, role, bits)

    def refund(self, ticket: int) -> None:
        """Give back a run that taught its requester nothing."""
        self.store.forget_run(ticket)
