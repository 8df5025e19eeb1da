"""A simulated shared radio channel, and the in-memory medium built on it.

:class:`Channel` decides who hears a frame and when: seeded random loss, bit corruption and
truncation, duplication, reordering (extra delay) and latency per receiver, plus the physics a
single LoRa channel has -- a frame that overlaps another transmission is lost (collision) and a
half-duplex node hears nothing while it transmits.  With a ``reach`` (radio range, a busy sky)
a node hears, senses and is disturbed only by the radios in its reach.  :class:`SimMedium`
attaches any number of nodes to one channel in the same process; the UDP hub (``udp``) reuses
the channel so that separate processes share it.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field

from companion.radio.clock import Clock
from companion.radio.transport import Receiver


@dataclass(frozen=True, slots=True)
class Impairments:
    """Per-receiver probabilities and delays of the simulated channel."""

    loss: float = 0.0
    corrupt: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    latency_s: float = 0.002
    reorder_delay_s: float = 1.0  # a reordered frame arrives up to this much later

    def __post_init__(self) -> None:
        for name in ("loss", "corrupt", "duplicate", "reorder"):
            value = getattr(self, name)
            if not 0.0 <= value < 1.0:
                raise ValueError(f"{name} probability {value} outside [0, 1)")
        if self.latency_s < 0 or self.reorder_delay_s < 0:
            raise ValueError("delays must be non-negative")


@dataclass
class ChannelStats:
    transmitted: int = 0
    delivered: int = 0
    lost: int = 0
    corrupted: int = 0
    duplicated: int = 0
    reordered: int = 0
    collisions: int = 0
    half_duplex: int = 0


@dataclass(slots=True)
class OnAir:
    src: int
    data: bytes
    start: float
    end: float
    freq: int = 0  # which of the region's channels


@dataclass
class Channel:
    impairments: Impairments = field(default_factory=Impairments)
    seed: int | None = None
    collisions: bool = True
    carrier_sense: bool = True  # radios detect channel activity before they transmit
    stats: ChannelStats = field(default_factory=ChannelStats)
    # reach(a, b): node b's radio is within range of node a's now (None: all hear all)
    reach: Callable[[int, int], bool] | None = None
    keep_log: bool = False  # keep (start, end, src) of every transmission in ``log``

    def __post_init__(self) -> None:
        # A simulation's random source: seeded for reproducible runs, never used for keys.
        self._rng = random.Random(self.seed)  # noqa: S311
        self._air: list[OnAir] = []
        self.nodes: set[int] = set()
        self.log: list[tuple[float, float, int]] = []
        self._longest = 0.0  # the longest frame yet on the air
        # one transceiver per node: the channel it is tuned to, and since when
        self.tuned: dict[int, tuple[int, float]] = {}

    def tune(self, node: int, freq: int, now: float) -> None:
        """Node ``node``'s radio listens (and sends) on channel ``freq`` from ``now`` on."""
        if self.tuned.get(node, (0, 0.0))[0] != freq:
            self.tuned[node] = (freq, now)

    def _freq(self, node: int) -> int:
        return self.tuned[node][0] if node in self.tuned else 0

    def begin(self, src: int, data: bytes, start: float, airtime: float) -> OnAir:
        self._air = [t for t in self._air if t.end > start - 60.0]
        tx = OnAir(src, data, start, start + airtime, self._freq(src))
        self._longest = max(self._longest, airtime)
        self._air.append(tx)
        self.stats.transmitted += 1
        if self.keep_log:
            self.log.append((start, tx.end, src))
        return tx

    def busy(self, node: int, now: float) -> bool:
        """Another node's frame is on the air at ``now`` (what LoRa channel activity
        detection tells a radio before it transmits)."""
        reach, freq = self.reach, self._freq(node)
        for t in reversed(self._air):  # (in the order they began)
            if t.start < now - self._longest:
                return False  # all earlier ones have ended
            if (
                t.src != node
                and t.freq == freq
                and t.start <= now < t.end
                and (reach is None or reach(t.src, node))
            ):
                return True
        return False

    def end(self, tx: OnAir) -> list[tuple[int, float, bytes]]:
        """Who receives ``tx``: (node, delay after the end of transmission, bytes)."""
        overlapping = [
            t
            for t in self._air
            if t is not tx and t.start < tx.end and t.end > tx.start and t.freq == tx.freq
        ]
        collided = self.collisions and any(t.src != tx.src for t in overlapping)
        out: list[tuple[int, float, bytes]] = []
        imp, rng, reach = self.impairments, self._rng, self.reach
        for node in sorted(self.nodes - {tx.src}):
            if node in self.tuned:
                freq, since = self.tuned[node]
                if freq != tx.freq or since > tx.start:
                    continue  # listening elsewhere (for part of the frame at least)
            elif tx.freq != 0:
                continue
            if reach is not None:
                if not reach(tx.src, node):
                    continue  # out of range: not even noise
                collided = self.collisions and any(
                    t.src not in (tx.src, node) and reach(t.src, node) for t in overlapping
                )
            if any(t.src == node for t in overlapping):
                self.stats.half_duplex += 1
                continue
            if collided:
                self.stats.collisions += 1
                continue
            if rng.random() < imp.loss:
                self.stats.lost += 1
                continue
            data = tx.data
            if rng.random() < imp.corrupt:
                data = self._corrupt(data)
                self.stats.corrupted += 1
            delay = imp.latency_s
            if rng.random() < imp.reorder:
                delay += rng.uniform(0.0, imp.reorder_delay_s)
                self.stats.reordered += 1
            out.append((node, delay, data))
            if rng.random() < imp.duplicate:
                out.append((node, delay + rng.uniform(0.0, imp.reorder_delay_s), data))
                self.stats.duplicated += 1
        self.stats.delivered += len(out)
        return out

    def _corrupt(self, data: bytes) -> bytes:
        rng = self._rng
        if data and rng.random() < 0.2:
            return data[: rng.randrange(len(data))]  # truncated reception
        buf = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            position = rng.randrange(len(buf))
            buf[position] ^= 1 << rng.randrange(8)
        return bytes(buf)


class SimMedium:
    """Nodes in one process sharing a :class:`Channel` on a (usually virtual) clock."""

    def __init__(self, channel: Channel | None = None, clock: Clock | None = None) -> None:
        self.channel = channel or Channel()
        self.clock = clock or Clock()
        self._receivers: dict[int, Receiver | None] = {}

    def attach(self, node: int) -> SimTransport:
        if node in self._receivers:
            raise ValueError(f"node {node} already attached")
        self._receivers[node] = None
        self.channel.nodes.add(node)
        return SimTransport(self, node)

    def _deliver(self, node: int, data: bytes) -> None:
        receiver = self._receivers.get(node)
        if receiver is not None:
            receiver(data)


class SimTransport:
    def __init__(self, medium: SimMedium, node: int) -> None:
        self.medium = medium
        self.node = node

    def set_receiver(self, callback: Receiver) -> None:
        self.medium._receivers[self.node] = callback

    def tune(self, freq: int) -> None:
        """Listen and send on channel ``freq`` of the region (0: the common one)."""
        self.medium.channel.tune(self.node, freq, self.medium.clock.now())

    def channel_busy(self) -> bool:
        channel = self.medium.channel
        return channel.carrier_sense and channel.busy(self.node, self.medium.clock.now())

    async def transmit(self, frame: bytes, airtime: float) -> None:
        clock = self.medium.clock
        tx = self.medium.channel.begin(self.node, frame, clock.now(), airtime)
        await clock.sleep(airtime)
        for node, delay, data in self.medium.channel.end(tx):
            clock.call_later(delay, self.medium._deliver, node, data)

    async def close(self) -> None:
        self.medium._receivers.pop(self.node, None)
        self.medium.channel.nodes.discard(self.node)
