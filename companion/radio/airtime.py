"""Time on air, link profiles and the duty-cycle budget (pure: times are arguments).

Semtech AN1200.13 (LoRa modem designer's guide), for a frame of ``PL`` bytes::

    T_sym      = 2^SF / BW
    T_preamble = (n_preamble + 4.25) T_sym
    n_payload  = 8 + max(ceil((8 PL - 4 SF + 28 + 16 CRC - 20 IH) / (4 (SF - 2 DE))) (CR + 4), 0)

with explicit header (IH = 0), CRC on, and low-data-rate optimisation DE = 1 when T_sym > 16 ms.
The regulatory side: EU868 (868.0-868.6 MHz) allows 1 % duty cycle, and its 869.4-869.65 MHz
sub-band (g3) 10 %, enforced here as a transmit budget over a sliding hour; US915 has no duty
cycle but a 400 ms dwell time per frame, which caps the frame size at slow spreading factors.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

EPSILON = 1e-6  # seconds: float slack when an hour-old transmission leaves the window
PHY_MAX_FRAME = 255  # LoRa PHY payload limit (bytes)
DEFAULT_MTU = 222  # LoRaWAN's limit at SF7-8 in EU868: the default frame size


def lora_airtime(
    payload_bytes: int,
    sf: int,
    bw_hz: int = 125_000,
    cr: int = 1,
    preamble: int = 8,
    *,
    explicit_header: bool = True,
    crc: bool = True,
) -> float:
    """Seconds on air of one LoRa frame (AN1200.13); ``cr`` 1..4 means coding rate 4/(4+cr)."""
    if not 6 <= sf <= 12 or not 1 <= cr <= 4 or payload_bytes < 0:
        raise ValueError(f"bad LoRa parameters sf={sf} cr={cr} bytes={payload_bytes}")
    t_sym = (1 << sf) / bw_hz
    de = 1 if t_sym > 0.016 else 0
    ih = 0 if explicit_header else 1
    numerator = 8 * payload_bytes - 4 * sf + 28 + 16 * int(crc) - 20 * ih
    n_payload = 8 + max(math.ceil(numerator / (4 * (sf - 2 * de))) * (cr + 4), 0)
    return (preamble + 4.25) * t_sym + n_payload * t_sym


@dataclass(frozen=True, slots=True)
class LinkProfile:
    """A radio and its regulation.  ``sf = 0`` means a plain FSK-class radio at ``bitrate``."""

    name: str
    description: str
    sf: int = 0
    bw_hz: int = 125_000
    cr: int = 1
    bitrate: int = 0
    duty_cycle: float | None = None  # fraction of time on air allowed per window
    duty_window_s: float = 3600.0
    dwell_s: float | None = None  # longest single frame allowed on air
    mtu: int = DEFAULT_MTU
    turnaround_s: float = 0.010  # RX->TX switch and MCU handling per frame
    channels: int = 1  # channels of the region a link may spread its sessions over

    def airtime(self, frame_bytes: int) -> float:
        """Seconds one frame of ``frame_bytes`` occupies the channel."""
        if self.sf:
            return lora_airtime(frame_bytes, self.sf, self.bw_hz, self.cr)
        return (frame_bytes + 8) * 8 / self.bitrate  # 8 bytes preamble + sync word

    @property
    def budget_wait_s(self) -> float:
        """Longest a frame may wait for the duty-cycle budget before it leaves: a window."""
        return self.duty_window_s if self.duty_cycle else 0.0

    @property
    def max_frame(self) -> int:
        """Largest frame allowed: the MTU, the PHY limit, and the dwell time (US915)."""
        limit = min(self.mtu, PHY_MAX_FRAME)
        if self.dwell_s is not None:
            while limit > 0 and self.airtime(limit) > self.dwell_s:
                limit -= 1
        return limit

    @property
    def budget_s(self) -> float | None:
        """Seconds on air allowed per duty window (None: unconstrained)."""
        return None if self.duty_cycle is None else self.duty_cycle * self.duty_window_s

    def with_mtu(self, mtu: int) -> LinkProfile:
        if not 32 <= mtu <= PHY_MAX_FRAME:
            raise ValueError(f"MTU {mtu} outside 32..{PHY_MAX_FRAME}")
        return replace(self, mtu=mtu)


def _lora(name: str, sf: int, region: str) -> LinkProfile:
    if region == "eu868":  # the three default channels, 868.1/868.3/868.5 MHz
        return LinkProfile(
            name,
            f"LoRa SF{sf}/125 kHz CR4/5, EU868 1 % duty cycle",
            sf,
            125_000,
            duty_cycle=0.01,
            channels=3,
        )
    if region == "eu868-g3":
        return LinkProfile(
            name,
            f"LoRa SF{sf}/125 kHz CR4/5, EU868 869.4-869.65 MHz sub-band, 10 % duty cycle",
            sf,
            125_000,
            duty_cycle=0.10,
        )
    return LinkProfile(  # a sub-band: eight 125 kHz uplink channels
        name,
        f"LoRa SF{sf}/125 kHz CR4/5, US915 400 ms dwell",
        sf,
        125_000,
        dwell_s=0.400,
        channels=8,
    )


PROFILES: dict[str, LinkProfile] = {
    p.name: p
    for p in (
        _lora("eu868-sf7", 7, "eu868"),
        _lora("eu868-sf9", 9, "eu868"),
        _lora("eu868-sf12", 12, "eu868"),
        _lora("eu868-g3-sf7", 7, "eu868-g3"),
        _lora("us915-sf7", 7, "us915"),
        _lora("us915-sf9", 9, "us915"),
        LinkProfile(
            "ideal",
            "FSK-class radio at 250 kbit/s, no regulatory limit",
            bitrate=250_000,
            mtu=PHY_MAX_FRAME,
            turnaround_s=0.002,
        ),
    )
}


def profile(name: str) -> LinkProfile:
    """Look a profile up by its stable command-line name."""
    try:
        return PROFILES[name]
    except KeyError:
        raise ValueError(f"unknown link profile {name!r}; known: {', '.join(PROFILES)}") from None


class DutyCycle:
    """Sliding-window transmit budget (ETSI EN 300 220: time on air per observation hour).

    A share ``reserve`` of the budget is kept for control frames (acknowledgements, polls), so
    a node that has spent its data budget can still acknowledge its peer's data.
    """

    def __init__(self, budget_s: float | None, window_s: float, reserve: float = 0.1) -> None:
        self.budget_s = budget_s
        self.window_s = window_s
        self.reserve = reserve
        self._sent: deque[tuple[float, float]] = deque()  # (start, airtime)
        self._used = 0.0

    def _expire(self, now: float) -> None:
        while self._sent and self._sent[0][0] <= now - self.window_s + EPSILON:
            self._used -= self._sent.popleft()[1]
        if not self._sent:
            self._used = 0.0

    def earliest(self, now: float, airtime: float, *, control: bool = False) -> float:
        """Earliest start time >= now at which ``airtime`` more fits the budget."""
        if self.budget_s is None:
            return now
        limit = self.budget_s if control else self.budget_s * (1.0 - self.reserve)
        if airtime > limit:
            raise ValueError(f"a {airtime:.3f} s frame can never fit a {limit:.3f} s budget")
        self._expire(now)
        used, start = self._used, now
        for sent_at, length in self._sent:
            if used + airtime <= limit + 1e-12:
                break
            used -= length
            start = sent_at + self.window_s
        return now if start <= now + EPSILON else start

    def record(self, start: float, airtime: float) -> None:
        if self.budget_s is None:
            return
        self._sent.append((start, airtime))
        self._used += airtime
