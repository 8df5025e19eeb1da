"""What a run will cost before it starts: its volume parameters, its messages' sizes and the
link seconds they take on our profile (:func:`companion.runs.failsafe.run_seconds`).  Alice's
runs, the fail-safe's watch and its guard all reckon with these."""

from __future__ import annotations

from companion.mission.schedule import run_volumes
from companion.radio.endpoint import LinkEndpoint
from companion.runs.failsafe import run_seconds
from companion.settings import CompanionSettings
from protocol.compact.plan import message_sizes
from protocol.geo.grid import GridSpec
from protocol.geo.volumes import CROSSING, VolumeSpec
from protocol.intersection import Alice
from protocol.messages import Suite


class RunEstimates:
    def __init__(self, settings: CompanionSettings, endpoint: LinkEndpoint) -> None:
        self.settings = settings
        self.endpoint = endpoint

    def volumes(self, grid: GridSpec, epoch_s: int = 0) -> VolumeSpec:
        """The volume parameters of our runs on ``grid`` (the compact suite's; the paper
        suite compares the crossing only)."""
        if self.settings.suite is not Suite.COMPACT:
            return CROSSING
        return run_volumes(self.settings.separation, grid.resolution_mm, epoch_s)

    def seconds(
        self,
        m: int,
        grid: GridSpec,
        *,
        fresh: bool,
        n: int | None = None,
        skip: int = 0,
        stall_loss: float | None = None,
    ) -> float:
        """Link seconds an m x n run (n unknown: Bob's size taken as Alice's) will need from
        now, its first ``skip`` messages already exchanged (``stall_loss``: see
        :func:`~companion.runs.failsafe.run_seconds`); 0 for the paper suite, which has no
        size model."""
        if self.settings.suite is not Suite.COMPACT:
            return 0.0
        sizes = message_sizes(
            m,
            m if n is None else n,
            grid,
            fresh_setup=fresh,
            ot_security=self.settings.ot_security,
            volumes=self.volumes(grid),
        )[skip:]
        return run_seconds(
            sizes,
            self.endpoint.profile,
            loss=self.settings.failsafe.loss,
            duty=self.endpoint.duty,
            now=self.endpoint.clock.now(),
            stall_loss=stall_loss,
        )

    def run_bytes(self, alice: Alice, grid: GridSpec, *, fresh: bool) -> int | None:
        """Payload bytes the run is expected to move both ways (Bob's size guessed as
        Alice's until his first reply; None for the paper suite)."""
        if self.settings.suite is not Suite.COMPACT:
            return None
        n = alice.m if alice.n is None else alice.n
        sizes = message_sizes(
            alice.m,
            n,
            grid,
            fresh_setup=fresh,
            ot_security=self.settings.ot_security,
            volumes=self.volumes(grid),
        )
        return sum(size for _, size in sizes)
