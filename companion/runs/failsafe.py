"""Will a comparison's result arrive in time?  (pure: sizes, profile and clock are arguments)

Before and during a run Alice compares two times:

* the time the run still needs: its messages (their exact sizes are public before the run,
  :func:`protocol.compact.plan.message_sizes`) as frames on the profile, acknowledgements,
  turnarounds and the expected retransmissions, delayed further where her own duty-cycle
  budget runs out (the peer's is taken to be like hers); then the edit and the climb;
* the worst-case time until the peer could be here
(:func:`companion.neighbours.peers.time_to_meet`).

When the second is not larger than the first plus a margin, the result cannot be trusted to
arrive in time and she takes the configured precautionary action (climb over, or hold before,
the segments at risk: :func:`at_risk`).  It is the last line of defence: the look-ahead runs
exist so that it never has to act.
"""

from __future__ import annotations

import enum
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

from companion.mission.ground import reached_within, segment_distance_m
from companion.radio.airtime import DutyCycle, LinkProfile
from companion.radio.config import LinkConfig
from companion.radio.frames import MAX_ACK_BITMAP, OVERHEAD
from companion.radio.transmitter import LEAD_IDLE_S

Point = tuple[int, int]
LATENCY_S = LinkConfig().latency_allowance_s


class Action(enum.Enum):
    CLIMB = "climb"  # fly the segments within the peer's reach one level up
    HOLD = "hold"  # pause the mission before the first of them until the result arrives
    OFF = "off"  # only report


@dataclass(frozen=True)
class FailsafeSettings:
    action: Action = Action.CLIMB
    margin_s: float = 10.0  # on top of the estimate: edit upload, climb, slack
    # A late result is acted on no earlier than this (and the margin) before the peer could
    # be here: a run may still end in the meantime, and a peer that never comes closer (a
    # parallel track) needs nothing at all.  inf: at once, as soon as it is known late.
    lead_s: float = 20.0
    loss: float = 0.1  # frame loss the estimate allows for
    floor_m_s: float = 5.0  # speed assumed at least for any drone (hover may turn to flight)
    # Closer than this counts as reached: the separation (15 m by default) and as much again
    # for position errors (GNSS, the model).  The peer's position is as old as its beacon:
    # that age is counted on top, at its speed (``at_risk``'s ``peer_age_s``).
    reach_margin_m: float = 30.0


def run_seconds(
    sizes: Sequence[tuple[bool, int]],
    profile: LinkProfile,
    *,
    loss: float,
    duty: DutyCycle | None = None,
    now: float = 0.0,
    stall_loss: float | None = None,
    latency_s: float = LATENCY_S,
) -> float:
    """Expected seconds of link time for messages (sent by Alice?, bytes), one after the
    other, as the link's selective-repeat ARQ (:mod:`companion.radio.arq`) sends them: each
    fragment until it arrives (``1 / (1 - loss)`` times); a burst per round of what is still
    missing, each answered by one ACK and started on a channel idle for
    :data:`~companion.radio.transmitter.LEAD_IDLE_S`; and a lost ACK request or ACK (probability
    ``1 - (1 - loss)^2`` per burst) costs a retransmission timeout (the endpoint's model:
    a frame, an ACK and two turnarounds with the latency allowance; jittered, 1.25 of it on
    average) and a probe.  Calibrated on the simulated link: the in-flight runs of US915 SF7
    at 10 % loss took 31-35 s (full, 16 messages) where this says 36 s, 35-41 s (near, a
    fresh OT setup's computing included) where it says 36.5 s; the airtime alone, 28-29 s.

    Where Alice's own duty-cycle budget cannot carry her share (her data airtime at
    ``stall_loss``, by default ``loss``), the run waits for old transmissions to leave the
    window.  ``stall_loss=0``: only a wait that even a lossless run cannot escape -- the
    watch of a run under way counts a wait that may not come when it comes."""
    payload = profile.max_frame - OVERHEAD
    full = profile.airtime(profile.max_frame)
    ack = profile.airtime(OVERHEAD + 2 + MAX_ACK_BITMAP)
    rto = full + ack + 2 * (profile.turnaround_s + latency_s)
    delivered = (1.0 - loss) ** 2  # an ACK request and its ACK both arrive
    per_burst = ack + 2 * profile.turnaround_s + (1 - delivered) / delivered * (1.25 * rto + ack)
    per_burst += LEAD_IDLE_S  # a burst starts on a channel idle for a moment
    total = 0.0
    spent = 0.0  # Alice's data airtime (duty-cycle budget)
    for alice_sends, size in sizes:
        frames = max(1, math.ceil(size / payload))
        last = size - (frames - 1) * payload
        airtime = (frames - 1) * full + profile.airtime(last + OVERHEAD)
        # Bursts: the first, and one more while any fragment is still missing.
        bursts = math.ceil(frames / 64) + sum(1.0 - (1.0 - loss**k) ** frames for k in range(1, 8))
        total += airtime / (1.0 - loss) + frames * profile.turnaround_s + bursts * per_burst
        if alice_sends:
            spent += airtime / (1.0 - (loss if stall_loss is None else stall_loss))
    if duty is not None and duty.budget_s is not None:
        start = duty.earliest(now, min(spent, duty.budget_s * (1 - duty.reserve)))
        total += max(start - now, 0.0)
        if spent > duty.budget_s * (1 - duty.reserve):  # more than one window's budget
            total += (spent / (duty.budget_s * (1 - duty.reserve)) - 1) * duty.window_s
    return total


def too_late(seconds_needed: float, seconds_to_meet: float, settings: FailsafeSettings) -> bool:
    """A result ``seconds_needed`` from now comes too late for a peer that could be here in
    ``seconds_to_meet`` (less the margin): what runs are planned by."""
    return seconds_to_meet <= seconds_needed + settings.margin_s


def act_now(
    seconds_needed: float,
    seconds_to_meet: float,
    earliest_s: float,
    settings: FailsafeSettings,
) -> bool:
    """The precaution is due: the result comes too late for the peer's expected meeting
    (:func:`too_late`, ``seconds_to_meet``: at the measured closing rate, where fresh) and
    the peer could *at the earliest* (``earliest_s``: flying straight at us, never sooner)
    be here within the lead and the margin -- the last check before it could.  Acting as
    soon as a result is known late climbed for every neighbour on a parallel track 800 m away
    whose run waited behind others (busy_ten: 10-13 false alarms a replay); waiting until
    the last moment lets the run end meanwhile, and a peer that never comes closer never
    gets that close.  The measured closing rate is no bound (two drones nearing a crossing
    at a slant held it at 35 s while they closed in): the lead counts from the earliest."""
    lead = min(seconds_needed, settings.lead_s)
    return too_late(seconds_needed, seconds_to_meet, settings) and (
        earliest_s <= lead + settings.margin_s
    )


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
    left: Sequence[float] | None = None,
) -> list[int]:
    """Segments (``first`` + k of ``path``) a precaution must cover if the result may take
    ``seconds`` more: those the peer could reach by then *and* we enter by then, plus the
    margin; a segment we enter later hears the result first, and ``decided`` ones (a
    finished run compared them) need nothing.  When we enter ours is ``entered`` (the
    earliest second from now of each, the start of its time window: the schedule's, the
    same the runs compare); without it, each drone flying at least ``floor_m_s``.  When we
    leave them is ``left`` (the ends of the windows, late by our tolerance): a segment we
    have left before the peer could reach it is not at risk either.  The peer's position
    is ``peer_age_s`` old: it may have flown that long already."""
    window = seconds + settings.margin_s
    speed = max(peer_speed_m_s, settings.floor_m_s)
    age = max(peer_age_s, 0.0)
    if entered is not None:
        ours = {first + k for k, start in enumerate(entered) if start <= window}
    else:
        ahead = max(own_speed_m_s, settings.floor_m_s) * window + settings.reach_margin_m
        ours = reached_within(path, first, here, ahead)
    risky = []
    for k, (a, b) in enumerate(itertools.pairwise(path)):
        if first + k not in ours or first + k in decided:
            continue
        # The earliest second from now the peer could be within reach of this segment.
        arrives = max(segment_distance_m(peer, a, b) - settings.reach_margin_m, 0.0) / speed - age
        if arrives <= window and (left is None or k >= len(left) or arrives <= left[k]):
            risky.append(first + k)
    return risky
