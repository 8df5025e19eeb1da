"""Will a comparison's result arrive in time?  (pure: sizes, profile and clock are arguments)

Before and during a run Alice compares two times:

* the time the run still needs: its messages (their exact sizes are public before the run,
  :func:`protocol.compact_plan.message_sizes`) as frames on the profile, acknowledgements,
  turnarounds and the expected retransmissions, delayed further where her own duty-cycle
  budget runs out (the peer's is taken to be like hers); then the edit and the climb;
* the worst-case time until the peer could be here (:func:`companion.peers.time_to_meet`).

When the second is not larger than the first plus a margin, the result cannot be trusted to
arrive in time and she takes the configured precautionary action (climb over, or hold before,
the segments at risk: :func:`at_risk`).  It is the last line of defence: the look-ahead runs
exist so that it never has to act.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

from .link.airtime import DutyCycle, LinkProfile
from .link.frames import MAX_ACK_BITMAP, OVERHEAD
from .peers import reached_within, segments_within

Point = tuple[int, int]


class Action(enum.Enum):
    CLIMB = "climb"  # fly the segments within the peer's reach one level up
    HOLD = "hold"  # pause the mission before the first of them until the result arrives
    OFF = "off"  # only report


@dataclass(frozen=True)
class FailsafeSettings:
    action: Action = Action.CLIMB
    margin_s: float = 10.0  # on top of the estimate: edit upload, climb, slack
    loss: float = 0.1  # frame loss the estimate allows for
    floor_m_s: float = 5.0  # speed assumed at least for any drone (hover may turn to flight)
    reach_margin_m: float = 100.0


def run_seconds(
    sizes: Sequence[tuple[bool, int]],
    profile: LinkProfile,
    *,
    loss: float,
    duty: DutyCycle | None = None,
    now: float = 0.0,
) -> float:
    """Seconds of link time for messages (sent by Alice?, bytes), one after the other."""
    payload = profile.max_frame - OVERHEAD
    full = profile.airtime(profile.max_frame)
    ack = profile.airtime(OVERHEAD + 2 + MAX_ACK_BITMAP)
    total = 0.0
    spent = 0.0  # Alice's airtime so far (duty-cycle budget)
    for alice_sends, size in sizes:
        frames = max(1, math.ceil(size / payload))
        last = size - (frames - 1) * payload
        airtime = (frames - 1) * full + profile.airtime(last + OVERHEAD)
        bursts = math.ceil(frames / 64)
        message = (airtime + bursts * ack) / (1.0 - loss) + 2 * frames * profile.turnaround_s
        total += message
        if alice_sends:
            spent += airtime / (1.0 - loss)
    if duty is not None and duty.budget_s is not None:
        start = duty.earliest(now, min(spent, duty.budget_s * (1 - duty.reserve)))
        total += max(start - now, 0.0)
        if spent > duty.budget_s * (1 - duty.reserve):  # more than one window's budget
            total += (spent / (duty.budget_s * (1 - duty.reserve)) - 1) * duty.window_s
    return total


def too_late(seconds_needed: float, seconds_to_meet: float, settings: FailsafeSettings) -> bool:
    return seconds_to_meet <= seconds_needed + settings.margin_s


def at_risk(
    path: Sequence[Point],
    first: int,
    here: Point | None,
    own_speed_m_s: float,
    peer: Point,
    peer_speed_m_s: float,
    seconds: float,
    settings: FailsafeSettings,
    decided: set[int] | frozenset[int] = frozenset(),
    *,
    peer_age_s: float = 0.0,
    entered: Sequence[float] | None = None,
) -> list[int]:
    """Segments (``first`` + k of ``path``) a precaution must cover if the result may take
    ``seconds`` more: those the peer could reach by then *and* we enter by then, plus the
    margin; a segment we enter later hears the result first, and ``decided`` ones (a
    finished run compared them) need nothing.  When we enter ours is ``entered`` (the
    earliest second from now of each, the start of its time window: the schedule's, the
    same the runs compare); without it, each drone flying at least ``floor_m_s``.  The
    peer's position is ``peer_age_s`` old: it may have flown that long already."""
    window = seconds + settings.margin_s
    reach = (
        max(peer_speed_m_s, settings.floor_m_s) * (window + max(peer_age_s, 0.0))
        + settings.reach_margin_m
    )
    if entered is not None:
        ours = {first + k for k, start in enumerate(entered) if start <= window}
    else:
        ahead = max(own_speed_m_s, settings.floor_m_s) * window + settings.reach_margin_m
        ours = reached_within(path, first, here, ahead)
    return [k for k in segments_within(path, first, peer, reach) if k in ours and k not in decided]
