"""The mission protocol of the mock autopilot: stores, downloads, uploads, clears.

Mission, fence and rally stores.  Download: REQUEST_LIST -> COUNT, REQUEST_INT -> ITEM_INT,
legacy REQUEST -> ITEM (float degrees, non-INT frame).  Upload, driven by the autopilot:
COUNT -> REQUEST_INT 0..n-1 (re-requested every 0.25 s, cancelled after 8 silent tries),
answered with ITEM_INT or legacy ITEM.  Each item is checked as it arrives: an unsupported
command (MAV_MISSION_UNSUPPORTED) or frame (MAV_MISSION_UNSUPPORTED_FRAME; a number that is
no MAV_FRAME for every personality) refuses the whole upload and keeps the old mission --
ArduPilot answers the offending item at once, PX4 (measured, docs/px4-sitl-findings.md) asks
for the rest and refuses with the final MISSION_ACK.  Uploads are atomic: the store changes
only when the last item arrived, and holds each item as the firmware reads it back
(:meth:`Personality.stored`); ArduPilot's item 0 is always its home.  One upload at a time
over all links: a newer MISSION_COUNT cancels the one in progress.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from companion.mission.items import FRAMES_GLOBAL, MissionItem
from companion.mission.personalities import Firmware, Personality
from companion.sim.mock_links import Faults, Link

ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
MISSION_TYPE_ALL = mavlink.MAV_MISSION_TYPE_ALL  # 255: CLEAR_ALL of every type
MISSION_FRAME = 2  # MAV_FRAME_MISSION: x/y are plain parameters
LEGACY_FRAMES = {5: 0, 6: 3, 11: 10}  # the _INT frames' twins for MISSION_ITEM
RETRY_S, RETRIES = 0.25, 8  # the autopilot drives uploads: it re-requests lost items


def _xy_scale(frame: int) -> float:
    """MISSION_ITEM_INT x/y per MISSION_ITEM x/y: degE7, metres * 1e4 (local), or 1."""
    if frame in FRAMES_GLOBAL:
        return 1e7
    return 1.0 if frame == MISSION_FRAME else 1e4


def item_message(
    mav: Any, target_system: int, target_component: int, it: MissionItem, *, legacy: bool = False
) -> Any:
    """MISSION_ITEM_INT for one item; ``legacy``: MISSION_ITEM (x/y float: degrees in global
    frames) in the non-INT twin of its frame (PX4 measured: 3 where MISSION_ITEM_INT says 6)."""
    head = (target_system, target_component, it.seq)
    params = (it.command, it.current, it.autocontinue, it.param1, it.param2, it.param3, it.param4)
    if legacy:
        scale = _xy_scale(it.frame)
        frame = LEGACY_FRAMES.get(it.frame, it.frame)
        return mav.mission_item_encode(
            *head, frame, *params, it.x / scale, it.y / scale, it.z, it.mission_type
        )
    return mav.mission_item_int_encode(*head, it.frame, *params, it.x, it.y, it.z, it.mission_type)


def item_from(m: Any, *, legacy: bool) -> MissionItem:
    """The item of a MISSION_ITEM_INT, or of a legacy MISSION_ITEM (degrees -> degE7)."""
    x, y = m.x, m.y
    if legacy:
        scale = _xy_scale(m.frame)
        finite = math.isfinite(x) and math.isfinite(y)
        x, y = (round(x * scale), round(y * scale)) if finite else (0, 0)
    return MissionItem(
        m.seq,
        m.frame,
        m.command,
        m.current,
        m.autocontinue,
        m.param1,
        m.param2,
        m.param3,
        m.param4,
        int(x),
        int(y),
        m.z,
        m.mission_type,
    )


@dataclass
class _Upload:
    link: Link
    mission_type: int
    count: int
    items: list[MissionItem] = field(default_factory=list)
    tries: int = 0
    timer: asyncio.TimerHandle | None = None
    refusal: int | None = None  # PX4: the first item's refusal, answered at the end


class MissionServer:
    """The mission protocol, a base of :class:`~companion.mock_autopilot.MockAutopilot`:
    the subclass sends (``_reply``) and decides what a new mission means in flight."""

    current: int
    mav: Any  # the subclass's encoder (messages are packed per link when sent)

    def __init__(
        self,
        personality: Personality,
        home: tuple[float, float, float],
        faults: Faults,
        mission: list[MissionItem] | None,
    ) -> None:
        self.personality = personality
        self.home = home
        self.faults = faults
        self.stores: dict[int, list[MissionItem]] = {0: [], 1: [], 2: []}
        if mission:  # held as given, as if the autopilot had loaded it itself
            self.stores[0] = [m.replace(seq=i, current=0) for i, m in enumerate(mission)]
        if personality.home_is_item0 and not self.stores[0]:
            self.stores[0] = [self._home_item()]
        self.uploads_accepted = 0
        self._upload: _Upload | None = None
        self._garbles_left = faults.garble_uploads

    @property
    def mission(self) -> list[MissionItem]:
        return self.stores[0]

    def _home_item(self) -> MissionItem:
        lat, lon, alt = self.home
        return MissionItem(0, 0, 16, 0, 1, 0, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), alt)

    # ------------------------------------------------------------------ subclass hooks

    def _reply(self, link: Link, message: Any) -> None:
        """Send a reply on ``link`` (faults apply)."""
        raise NotImplementedError

    def _mission_replaced(self, marked: int | None) -> None:
        """The mission store was replaced by an upload (``marked``: the item flagged current)."""
        raise NotImplementedError

    def _mission_cleared(self) -> None:
        raise NotImplementedError

    def _report_current(self) -> None:
        """Send MISSION_CURRENT on every link."""
        raise NotImplementedError

    # ------------------------------------------------------------------ download

    def _ack(self, link: Link, m: Any, result: int, mission_type: int) -> None:
        src, comp = m.get_srcSystem(), m.get_srcComponent()
        self._reply(link, self.mav.mission_ack_encode(src, comp, result, mission_type))

    def _on_mission_request_list(self, link: Link, m: Any) -> None:
        store = self.stores.get(m.mission_type, [])
        count = self.mav.mission_count_encode(
            m.get_srcSystem(), m.get_srcComponent(), len(store), m.mission_type
        )
        self._reply(link, count)

    def held(self, kind: int = 0) -> list[MissionItem]:
        """A store as a download gives it: the mission with the vehicle's current item marked."""
        return [
            it.replace(current=int(kind == 0 and seq == self.current))
            for seq, it in enumerate(self.stores.get(kind, []))
        ]

    def _on_mission_request_int(self, link: Link, m: Any, *, legacy: bool = False) -> None:
        store = self.held(m.mission_type)
        if not 0 <= m.seq < len(store):
            self._ack(link, m, mavlink.MAV_MISSION_INVALID_SEQUENCE, m.mission_type)
            return
        it = store[m.seq]
        self._reply(
            link, item_message(self.mav, m.get_srcSystem(), m.get_srcComponent(), it, legacy=legacy)
        )

    def _on_mission_request(self, link: Link, m: Any) -> None:
        self._on_mission_request_int(link, m, legacy=True)

    # ------------------------------------------------------------------ upload

    def _cancel_upload(self) -> None:
        if self._upload and self._upload.timer:
            self._upload.timer.cancel()
        self._upload = None

    def _on_mission_count(self, link: Link, m: Any) -> None:
        self._cancel_upload()  # the newer upload wins
        if self.faults.reject_upload is not None:
            self._ack(link, m, self.faults.reject_upload, m.mission_type)
            return
        if m.mission_type not in self.stores:
            self._ack(link, m, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)
            return
        if m.count == 0:
            self._commit(link, m, [])
            return
        self._upload = _Upload(link, m.mission_type, m.count)
        self._request(m)

    def _request(self, m: Any) -> None:
        up = self._upload
        if up is None:
            return
        src, comp = m.get_srcSystem(), m.get_srcComponent()
        request = self.mav.mission_request_int_encode(src, comp, len(up.items), up.mission_type)
        self._reply(up.link, request)
        if up.timer:
            up.timer.cancel()
        up.timer = asyncio.get_running_loop().call_later(RETRY_S, self._retry, m)

    def _retry(self, m: Any) -> None:
        up = self._upload
        if up is None:
            return
        up.tries += 1
        if up.tries > RETRIES:
            self._upload = None
            self._ack(up.link, m, mavlink.MAV_MISSION_OPERATION_CANCELLED, up.mission_type)
            return
        self._request(m)

    def _refusal(self, it: MissionItem) -> int | None:
        """Why the autopilot refuses this item as it arrives (None: it takes it)."""
        why = self.personality.refusal(it)
        return None if why is None else why[0].value

    def _on_mission_item_int(self, link: Link, m: Any, *, legacy: bool = False) -> None:
        up = self._upload
        if up is None or link is not up.link or m.mission_type != up.mission_type:
            return
        if m.seq == len(up.items):
            it = item_from(m, legacy=legacy)
            refusal = self._refusal(it)
            if refusal is not None and self.personality.firmware is Firmware.ARDUPILOT:
                self._cancel_upload()  # ArduPilot answers the offending item at once
                self._ack(link, m, refusal, up.mission_type)
                return
            up.refusal = up.refusal if up.refusal is not None else refusal
            up.items.append(it)
            up.tries = 0
        if len(up.items) < up.count:
            self._request(m)
            return
        self._cancel_upload()
        if up.refusal is not None:  # PX4 (measured): refused at the end, old mission kept
            self._ack(link, m, up.refusal, up.mission_type)
        else:
            self._commit(link, m, up.items)

    def _on_mission_item(self, link: Link, m: Any) -> None:
        self._on_mission_item_int(link, m, legacy=True)

    def _commit(self, link: Link, m: Any, items: list[MissionItem]) -> None:
        """The upload's last item arrived: store it (:meth:`store`) and acknowledge."""
        kind = m.mission_type
        self.store(kind, items)
        self._ack(link, m, ACCEPTED, kind)
        if kind == 0:
            self._report_current()

    def store(self, kind: int, items: list[MissionItem]) -> None:
        """Replace a store at once (never a mix), as the firmware holds the items: what an
        accepted upload does, over MAVLink or from a caller in this process."""
        marked = next((i for i, it in enumerate(items) if it.current), None)
        if self._garbles_left and items:  # a partial/garbled write, caught by read-back
            self._garbles_left -= 1
            items = [*items[:-1], items[-1].replace(z=items[-1].z + 1000.0)]
        if kind == 0:
            if self.personality.home_is_item0:  # ArduPilot reads its home back as item 0
                items = [self._home_item(), *items[1:]]
            items = [self.personality.stored(it) for it in items]
        self.stores[kind] = [it.replace(seq=i, current=0) for i, it in enumerate(items)]
        if kind == 0:
            self.uploads_accepted += 1
            self._mission_replaced(marked)

    # ------------------------------------------------------------------ clear

    def _on_mission_clear_all(self, link: Link, m: Any) -> None:
        kinds = list(self.stores) if m.mission_type == MISSION_TYPE_ALL else [m.mission_type]
        if not all(kind in self.stores for kind in kinds):
            self._ack(link, m, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)
            return
        self.clear(kinds)
        self._ack(link, m, ACCEPTED, m.mission_type)
        if 0 in kinds:
            self._report_current()

    def clear(self, kinds: list[int]) -> None:
        """Empty the stores ``kinds`` (ArduPilot keeps its home as item 0 of the mission)."""
        for kind in kinds:
            self.stores[kind] = []
        if 0 in kinds:
            if self.personality.home_is_item0:
                self.stores[0] = [self._home_item()]
            self._mission_cleared()
