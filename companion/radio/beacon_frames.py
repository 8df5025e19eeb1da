"""Beacons on frames: one broadcast frame, or a few fragments where frames are small.

A beacon is never acknowledged: where the profile's frames are smaller than the beacon (US915
SF9) it goes out as up to ``MAX_BEACON_FRAGMENTS`` BEACON frames sharing a sequence number,
and a receiver puts them together or drops the beacon whole.  Partial beacons are bounded in
number and age, so a stranger's fragments cost a receiver little.
"""

from __future__ import annotations

from companion.radio.arq import MessageTooLarge
from companion.radio.frames import BROADCAST, MAX_BEACON_FRAGMENTS, Frame, FrameType
from companion.radio.stats import LinkStats

PARTIAL_AGE_S = 30.0  # a beacon's fragments arrive within seconds; older parts are dropped
MAX_PARTIAL = 16  # beacons half received at once


def beacon_frames(node: int, seq: int, payload: bytes, payload_size: int) -> list[Frame]:
    """The frames of one beacon of ``node`` (sequence number ``seq``)."""
    count = max(1, -(-len(payload) // payload_size))
    if count > MAX_BEACON_FRAGMENTS:
        raise MessageTooLarge(f"beacon of {len(payload)} bytes needs {count} frames")
    return [
        Frame(
            FrameType.BEACON,
            node,
            BROADCAST,
            0,
            seq,
            i,
            count,
            payload[i * payload_size : (i + 1) * payload_size],
        )
        for i in range(count)
    ]


class BeaconParts:
    """Fragments of beacons heard, until each beacon is whole."""

    def __init__(self, stats: LinkStats) -> None:
        self.stats = stats
        self._parts: dict[tuple[int, int, int], tuple[float, dict[int, bytes]]] = {}

    def add(self, frame: Frame, now: float) -> bytes | None:
        """The whole beacon once all its fragments are in, else None."""
        if frame.count == 1:
            return frame.payload
        for key in [k for k, (t, _) in self._parts.items() if now - t > PARTIAL_AGE_S]:
            del self._parts[key]
        key = (frame.src, frame.seq, frame.count)
        _, parts = self._parts.setdefault(key, (now, {}))
        parts[frame.index] = frame.payload
        if len(parts) == frame.count and all(i in parts for i in range(frame.count)):
            del self._parts[key]
            return b"".join(parts[i] for i in range(frame.count))
        while len(self._parts) > MAX_PARTIAL:
            self.stats.drop("beacon_partial")
            del self._parts[next(iter(self._parts))]
        return None
