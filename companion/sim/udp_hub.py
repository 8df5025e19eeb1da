"""One simulated channel shared by separate processes: a UDP service on loopback.

The hub owns a :class:`~companion.sim.medium.Channel` (loss, corruption, collisions, ...) and
relays frames between the nodes registered with it (:class:`companion.radio.udp.UdpTransport`,
whose module gives the datagrams).  It checks every datagram strictly (kind, sizes, a
registered sender) and drops the rest.  Run one with ``python -m companion link-hub``.
"""

from __future__ import annotations

import asyncio
from typing import cast

from companion.radio.airtime import PHY_MAX_FRAME
from companion.radio.clock import Clock
from companion.radio.udp import REGISTER, TRANSMIT
from companion.sim.medium import Channel


class UdpHub(asyncio.DatagramProtocol):
    """The channel as a UDP service: ``await UdpHub.serve(channel, port=...)``."""

    def __init__(self, channel: Channel, clock: Clock) -> None:
        self.channel = channel
        self.clock = clock
        self.nodes: dict[int, tuple[str, int]] = {}
        self.dropped = 0
        self.transport: asyncio.DatagramTransport | None = None

    @classmethod
    async def serve(
        cls, channel: Channel, host: str = "127.0.0.1", port: int = 0, clock: Clock | None = None
    ) -> UdpHub:
        loop = asyncio.get_running_loop()
        _, hub = await loop.create_datagram_endpoint(
            lambda: cls(channel, clock or Clock()), local_addr=(host, port)
        )
        return hub

    @property
    def address(self) -> tuple[str, int]:
        assert self.transport is not None
        host, port = self.transport.get_extra_info("sockname")[:2]
        return host, port

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if len(data) == REGISTER.size and data[:1] == b"R":
            _, node = REGISTER.unpack(data)
            self.nodes[node] = addr  # the latest registration wins (a restarted process)
            self.channel.nodes.add(node)
            return
        elif (
            len(data) > TRANSMIT.size
            and data[:1] == b"T"
            and len(data) - TRANSMIT.size <= PHY_MAX_FRAME
        ):
            _, node, airtime_us = TRANSMIT.unpack_from(data)
            if self.nodes.get(node) == addr and airtime_us <= 60_000_000:
                tx = self.channel.begin(
                    node, data[TRANSMIT.size :], self.clock.now(), airtime_us / 1e6
                )
                self.clock.call_later(airtime_us / 1e6, self._finish, tx)
                return
        self.dropped += 1

    def _finish(self, tx: object) -> None:
        for node, delay, frame in self.channel.end(tx):  # type: ignore[arg-type]
            addr = self.nodes.get(node)
            if addr is not None:
                self.clock.call_later(delay, self._send, b"D" + frame, addr)

    def _send(self, data: bytes, addr: tuple[str, int]) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.sendto(data, addr)

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()
