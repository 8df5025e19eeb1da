"""What beacons cost on the air (pure): airtime of a beacon of any kind on a profile, the
interval a duty cycle stretches beacons to, and the table ``bench-link`` prints.

A beacon is one broadcast frame, or a few where the profile's frames are small (US915 SF9:
50 bytes of payload).  On a duty-cycled profile the interval is stretched so that beacons use
at most ``DUTY_SHARE`` of the budget (a beacon counted as tagged for one neighbour: as many
bytes as an unauthenticated beacon had, so the interval is what it was).
"""

from __future__ import annotations

from dataclasses import dataclass

from companion.neighbours.beacon import (
    BODY_SIZE,
    CERT_BEACON_SIZE,
    SIGNED_SIZE,
    TAG_SIZE,
    UNAUTHENTICATED_SIZE,
)
from companion.radio.airtime import LinkProfile
from companion.radio.frames import OVERHEAD

DUTY_SHARE = 0.05


def beacon_frames(profile: LinkProfile, size: int) -> int:
    return max(1, -(-size // (profile.max_frame - OVERHEAD)))


def beacon_airtime(profile: LinkProfile, size: int) -> float:
    """Seconds on the air of a beacon of ``size`` payload bytes (all its frames)."""
    payload = profile.max_frame - OVERHEAD
    frames = beacon_frames(profile, size)
    last = size - (frames - 1) * payload
    return (frames - 1) * profile.airtime(OVERHEAD + payload) + profile.airtime(OVERHEAD + last)


def beacon_interval(profile: LinkProfile, configured_s: float) -> float:
    """``configured_s``, stretched on a duty-cycled profile to keep beacons within the share."""
    if profile.duty_cycle is None:
        return configured_s
    airtime = beacon_airtime(profile, BODY_SIZE + TAG_SIZE)
    return max(configured_s, airtime / (DUTY_SHARE * profile.duty_cycle))


@dataclass(frozen=True, slots=True)
class BeaconCost:
    kind: str
    payload_bytes: int
    frames: int
    airtime_s: float
    share: float  # of airtime (or of the duty-cycle budget), sent at the profile's interval


KINDS = (
    ("unauthenticated (before: 24 B)", UNAUTHENTICATED_SIZE),
    ("tagged, 1 neighbour", BODY_SIZE + TAG_SIZE),
    ("tagged, 2 neighbours", BODY_SIZE + 2 * TAG_SIZE),
    ("signed", SIGNED_SIZE),
    ("certificate", CERT_BEACON_SIZE),
)


def beacon_costs(profile: LinkProfile, configured_s: float = 10.0) -> list[BeaconCost]:
    """Every kind of beacon on ``profile``: bytes, frames, airtime and the share of the
    channel's time (US915, ideal) or of the duty-cycle budget (EU868) it would take if every
    beacon at the interval were of that kind."""
    interval = beacon_interval(profile, configured_s)
    rows = []
    for kind, size in KINDS:
        airtime = beacon_airtime(profile, size)
        budget = interval * (profile.duty_cycle or 1.0)
        rows.append(BeaconCost(kind, size, beacon_frames(profile, size), airtime, airtime / budget))
    return rows
