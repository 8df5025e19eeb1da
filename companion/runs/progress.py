"""Progress of a run on the radio, logged while it lasts (a run takes minutes on LoRa).

A :class:`RunProgress` is started with a run and logs, every :data:`EVERY_S` link seconds,
the bytes and frames sent and received since the run began (every frame: acknowledgements,
retransmissions and beacons too), the bytes the run's messages are expected to take, the
airtime and duty-cycle wait so far, and the time left by the run's estimate.  It
reads the link endpoint's counters; it never touches the run.  While the run hears nothing
for :data:`SILENT_S` it warns once that the peer is silent.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import astuple, dataclass

from companion import logs
from companion.radio.endpoint import LinkEndpoint
from companion.radio.stats import LinkStats
from companion.roles import Role
from companion.tasks import spawn

log = logging.getLogger("companion.runs.progress")
EVERY_S = 15.0  # link seconds between progress lines
SILENT_S = 30.0  # nothing heard from the peer this long: a warning


@dataclass(frozen=True)
class Totals:
    """Counters of a run so far (the endpoint's, since the run's start)."""

    sent_bytes: int
    sent_frames: int
    received_bytes: int
    received_frames: int
    airtime_s: float
    duty_wait_s: float

    @classmethod
    def of(cls, stats: LinkStats) -> Totals:
        """The endpoint's counters now."""
        return cls(
            stats.bytes_sent,
            stats.frames_sent,
            stats.bytes_received,
            stats.frames_received,
            stats.airtime_s,
            stats.duty_wait_s,
        )

    def __sub__(self, start: Totals) -> Totals:
        return Totals(
            *(now - then for now, then in zip(astuple(self), astuple(start), strict=True))
        )


def _kb(n: int) -> str:
    return f"{n / 1000:.1f} KB"


class RunProgress:
    """Logs the progress of one run with ``peer`` (as ``role``)."""

    def __init__(
        self,
        node: int,
        endpoint: LinkEndpoint,
        peer: int,
        role: Role,
        *,
        expected_bytes: Callable[[], int | None] = lambda: None,
        ends_at: Callable[[], float | None] = lambda: None,
    ) -> None:
        self.node, self.endpoint, self.peer, self.role = node, endpoint, peer, role
        self.expected_bytes = expected_bytes
        self.ends_at = ends_at
        self.clock = endpoint.clock
        self.started = self.clock.now()
        self.start = Totals.of(endpoint.stats)
        self._task: asyncio.Task[None] | None = None

    def totals(self) -> Totals:
        return Totals.of(self.endpoint.stats) - self.start

    def __enter__(self) -> RunProgress:
        self._task = spawn(self._report(), name=f"progress {self.peer}", log=log)
        return self

    def __exit__(self, *_: object) -> None:
        if self._task is not None:
            self._task.cancel()

    async def _report(self) -> None:
        heard_at, heard, warned = self.clock.now(), 0, False
        while True:
            await self.clock.sleep(EVERY_S)
            now, done = self.clock.now(), self.totals()
            if done.received_frames != heard:
                heard_at, heard, warned = now, done.received_frames, False
            elif now - heard_at >= SILENT_S and not warned:
                warned = True
                logs.event(
                    log,
                    logging.WARNING,
                    "peer_silent",
                    f"node {self.node}: nothing heard from {self.peer} in the run",
                    peer=self.peer,
                    silent_s=round(now - heard_at, 1),
                )
            self.line(now, done)

    def line(self, now: float, done: Totals) -> None:
        """One progress line."""
        total = self.expected_bytes()
        share = f" (the run's messages: ~{_kb(total)} in all)" if total else ""
        ends = self.ends_at()
        left = None if ends is None else ends - now
        when = (
            ""
            if left is None
            else f"; about {left:.0f} s left"
            if left >= 0
            else f"; {-left:.0f} s over the estimate"
        )
        logs.event(
            log,
            logging.INFO,
            "run_progress",
            f"node {self.node}: run with {self.peer} as {self.role}, {now - self.started:.0f} s: "
            f"sent {_kb(done.sent_bytes)} in {done.sent_frames} frames, received "
            f"{_kb(done.received_bytes)} in {done.received_frames} frames{share}; airtime "
            f"{done.airtime_s:.1f} s, duty-cycle wait {done.duty_wait_s:.1f} s" + when,
            show=False,
            peer=self.peer,
            role=self.role,
            elapsed_s=round(now - self.started, 1),
            sent_bytes=done.sent_bytes,
            sent_frames=done.sent_frames,
            received_bytes=done.received_bytes,
            received_frames=done.received_frames,
            expected_bytes=total,
            airtime_s=round(done.airtime_s, 2),
            duty_wait_s=round(done.duty_wait_s, 2),
            left_s=None if left is None else round(left, 1),
        )
