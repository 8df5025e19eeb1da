"""Real I/O: the UDP hub (in-process and as a separate process) and a serial port (pty)."""

from __future__ import annotations

import asyncio
import os
import pty
import re
import sys
import tty

import pytest

from companion.radio import PROFILES, LinkEndpoint
from companion.radio.serial_port import SerialTransport
from companion.radio.udp import UdpTransport
from companion.runs.exchange import run_alice, serve_bob
from companion.sim.medium import Channel, Impairments
from companion.sim.udp_hub import UdpHub
from protocol.geo.geometry import path_hits
from protocol.geo.grid import GridKind, GridSpec
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.tools.compare import Party

IDEAL = PROFILES["ideal"]


async def _protocol_run(a: LinkEndpoint, b: LinkEndpoint) -> None:
    party = Party.generate(Suite.COMPACT)
    grid = GridSpec(GridKind.PLANE, 50)
    alice_path, bob_path = ((-40, 0), (0, 3), (40, 0)), ((0, -40), (2, 40))
    alice = Alice(alice_path, grid, setup=party.setup)
    bob = Bob(bob_path, setups=party.setups)

    async def bob_side() -> None:
        peer, session = await b.accept(timeout=30)
        await serve_bob(b, peer, session, bob, timeout=60)

    task = asyncio.create_task(bob_side())
    report = await run_alice(a, b.node, alice, timeout=60)
    await task
    assert report.hits == path_hits(alice_path, bob_path) == [False, True]


@pytest.mark.slow
@pytest.mark.asyncio
async def test_two_endpoints_over_the_udp_hub() -> None:
    channel = Channel(Impairments(loss=0.1, corrupt=0.02, reorder=0.05, reorder_delay_s=0.01), 3)
    hub = await UdpHub.serve(channel)
    try:
        a = LinkEndpoint(1, await UdpTransport.connect(1, hub.address), IDEAL)
        b = LinkEndpoint(2, await UdpTransport.connect(2, hub.address), IDEAL)
        async with a, b:
            await _protocol_run(a, b)
        assert channel.stats.lost > 0  # the run crossed a lossy channel
        assert hub.dropped == 0
    finally:
        hub.close()


@pytest.mark.slow
@pytest.mark.asyncio
async def test_separate_processes_share_one_channel() -> None:
    hub = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "companion",
        "link-hub",
        "--port",
        "0",
        "--loss",
        "0.05",
        "--seed",
        "2",
        stdout=asyncio.subprocess.PIPE,
    )
    try:
        assert hub.stdout is not None
        line = (await asyncio.wait_for(hub.stdout.readline(), 20)).decode()
        match = re.search(r"udp://([\d.]+):(\d+)", line)
        assert match, line
        address = (match.group(1), int(match.group(2)))
        a = LinkEndpoint(1, await UdpTransport.connect(1, address), IDEAL)
        b = LinkEndpoint(2, await UdpTransport.connect(2, address), IDEAL)
        async with a, b:
            await _protocol_run(a, b)
    finally:
        hub.terminate()
        out, _ = await asyncio.wait_for(hub.communicate(), 20)
    assert b"hub stopped" in out and hub.returncode == 0


@pytest.mark.asyncio
async def test_hub_drops_malformed_datagrams() -> None:
    hub = await UdpHub.serve(Channel())
    try:
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(
            asyncio.DatagramProtocol, remote_addr=hub.address
        )
        for junk in (b"X", b"R\x00", b"T\x00\x01\x00\x00\x00\x01" + b"x" * 300, b"T\x00\x09"):
            transport.sendto(junk)
        transport.sendto(b"T\x00\x07\x00\x00\x00\x01frame")  # node 7 never registered
        await asyncio.sleep(0.05)
        transport.close()
        assert hub.dropped == 5 and not hub.nodes
    finally:
        hub.close()


def _pty() -> tuple[int, str]:
    master, slave = pty.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    return master, os.ttyname(slave)


@pytest.mark.slow
@pytest.mark.asyncio
async def test_two_endpoints_over_serial_ports() -> None:
    """Two UARTs (ptys) joined by a 'radio' that forwards bytes in odd-sized chunks."""
    (m1, dev1), (m2, dev2) = _pty(), _pty()
    loop = asyncio.get_running_loop()
    for fd in (m1, m2):
        os.set_blocking(fd, False)

    def forward(src: int, dst: int) -> None:
        try:
            data = os.read(src, 4096)
        except BlockingIOError:
            return
        for i in range(0, len(data), 37):  # the modem cuts the stream into its own packets
            os.write(dst, data[i : i + 37])

    loop.add_reader(m1, forward, m1, m2)
    loop.add_reader(m2, forward, m2, m1)
    try:
        a = LinkEndpoint(1, SerialTransport.open(dev1), IDEAL)
        b = LinkEndpoint(2, SerialTransport.open(dev2), IDEAL)
        async with a, b:
            await _protocol_run(a, b)
            assert a.stats.frames_received > 0 and not a.stats.dropped
    finally:
        loop.remove_reader(m1)
        loop.remove_reader(m2)
        os.close(m1)
        os.close(m2)


@pytest.mark.asyncio
async def test_serial_line_noise_is_dropped() -> None:
    master, dev = _pty()
    radio = SerialTransport.open(dev)
    got: list[bytes] = []
    radio.set_receiver(got.append)
    # 600 bytes of noise without a delimiter, made so that no suffix of it is a valid COBS
    # block (random bytes are one about every 130 draws: a chunk the UART cut anywhere must
    # not decode by chance)
    noise = b"\x01" * 345 + b"\xfe" + b"\xff" * 254
    os.write(master, b"\x00\x03ab\x00" + b"\x00\x05\x01\x00" + noise + b"\x00")
    async with asyncio.timeout(10):  # the pty hands the bytes on when it gets to it
        while radio.dropped < 2:  # the malformed block, then the noise
            await asyncio.sleep(0.01)
    await radio.close()
    os.close(master)
    assert got == [b"ab"]
    assert radio.dropped >= 1
