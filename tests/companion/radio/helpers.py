"""Two endpoints on one simulated channel, and a transmission log."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

from companion.radio import Clock, LinkConfig, LinkEndpoint, LinkProfile
from companion.radio.transport import Receiver
from companion.sim.medium import Channel, Impairments, SimMedium, SimTransport


class LoggingTransport:
    """Wraps a transport and records (start, airtime, bytes) of every transmission."""

    def __init__(self, inner: SimTransport) -> None:
        self.inner = inner
        self.log: list[tuple[float, float, int]] = []

    def set_receiver(self, callback: Receiver) -> None:
        self.inner.set_receiver(callback)

    async def transmit(self, frame: bytes, airtime: float) -> None:
        self.log.append((self.inner.medium.clock.now(), airtime, len(frame)))
        await self.inner.transmit(frame, airtime)

    async def close(self) -> None:
        await self.inner.close()


@dataclass
class Pair:
    a: LinkEndpoint
    b: LinkEndpoint
    channel: Channel
    logs: dict[int, list[tuple[float, float, int]]] = field(default_factory=dict)


@asynccontextmanager
async def pair(
    link: LinkProfile,
    impairments: Impairments | None = None,
    seed: int | None = 1,
    config: LinkConfig | None = None,
) -> AsyncIterator[Pair]:
    clock = Clock()
    channel = Channel(impairments or Impairments(), seed)
    medium = SimMedium(channel, clock)
    ta, tb = LoggingTransport(medium.attach(1)), LoggingTransport(medium.attach(2))
    a = LinkEndpoint(1, ta, link, config, clock)
    b = LinkEndpoint(2, tb, link, config, clock)
    async with a, b:
        yield Pair(a, b, channel, {1: ta.log, 2: tb.log})
