"""A node's radio on a channel shared by separate processes over UDP on loopback.

The hub (:mod:`companion.sim.udp_hub`) owns a simulated channel and relays frames between
registered nodes in real time (optionally scaled).  Datagrams::

    node -> hub   b"R" node:u16                      register (repeat to keep alive)
    node -> hub   b"T" node:u16 airtime_us:u32 frame  a transmission starts now
    hub -> node   b"D" frame                          a reception (after airtime + latency)

Run one with ``python -m companion link-hub``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from typing import cast

from companion.radio.clock import Clock
from companion.radio.transport import Receiver
from companion.tasks import spawn

log = logging.getLogger("companion.radio")
REGISTER = struct.Struct(">cH")
TRANSMIT = struct.Struct(">cHI")


class UdpTransport(asyncio.DatagramProtocol):
    """A node's radio on a :class:`UdpHub`: ``await UdpTransport.connect(node, hub_addr)``."""

    def __init__(self, node: int, clock: Clock) -> None:
        self.node = node
        self.clock = clock
        self.hub: tuple[str, int] | None = None
        self.unreachable = 0  # datagrams the hub's host refused (nothing listens there)
        self._receiver: Receiver | None = None
        self.transport: asyncio.DatagramTransport | None = None
        self._keepalive: asyncio.Task[None] | None = None

    @classmethod
    async def connect(
        cls, node: int, hub: tuple[str, int], clock: Clock | None = None
    ) -> UdpTransport:
        loop = asyncio.get_running_loop()
        _, radio = await loop.create_datagram_endpoint(
            lambda: cls(node, clock or Clock()), remote_addr=hub
        )
        radio.hub = hub
        radio._register()
        radio._keepalive = spawn(radio._keep_registered(), name=f"link-keepalive-{node}", log=log)
        await asyncio.sleep(0.01)  # let the registration reach the hub first
        return radio

    def _register(self) -> None:
        if self.transport is not None:
            self.transport.sendto(REGISTER.pack(b"R", self.node))

    async def _keep_registered(self) -> None:
        while True:
            await asyncio.sleep(5.0)
            self._register()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def error_received(self, exc: Exception) -> None:
        """The hub's host refused a datagram: warn at the first and every 100th."""
        if self.unreachable % 100 == 0:
            host, port = self.hub or ("?", 0)
            log.warning(
                "node %d: the link hub at %s:%d is unreachable (%s): is `python -m companion "
                "link-hub --port %d` running?",
                self.node,
                host,
                port,
                exc.strerror if isinstance(exc, OSError) else exc,
                port,
            )
        self.unreachable += 1

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if data[:1] == b"D" and self._receiver is not None:
            self._receiver(data[1:])

    def set_receiver(self, callback: Receiver) -> None:
        self._receiver = callback

    async def transmit(self, frame: bytes, airtime: float) -> None:
        if self.transport is None or self.transport.is_closing():
            raise ConnectionError("UDP radio is closed")
        self.transport.sendto(TRANSMIT.pack(b"T", self.node, round(airtime * 1e6)) + frame)
        await self.clock.sleep(airtime)

    async def close(self) -> None:
        if self._keepalive is not None:
            self._keepalive.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._keepalive
        if self.transport is not None:
            self.transport.close()
