"""PX4's mission protocol from the ground station's side: upload, clear, download, current.

Each transfer holds the link's transfer lock (PX4 runs one transfer at a time) and re-sends
its last message until PX4 makes progress (:meth:`Px4Link._exchange`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from companion.mission.items import MissionItem
from companion.sim.mock_missions import item_from, item_message
from companion.sim.px4.build import MissionRefused
from companion.sim.px4.link import Px4Link

ACCEPTED = mavlink.MAV_MISSION_ACCEPTED


class Px4Missions(Px4Link):
    """Mission transfers over the ground station's link."""

    async def upload_mission(
        self,
        items: Sequence[MissionItem],
        *,
        mission_type: int = 0,
        legacy: bool = False,
        count_zero: bool = False,
    ) -> None:
        """Upload ``items`` (sent as numbers 0..n-1, flags as given) with MISSION_ITEM_INT
        (``legacy``: MISSION_ITEM); an empty list clears with MISSION_CLEAR_ALL (``count_zero``:
        with MISSION_COUNT 0).  :class:`MissionRefused` unless PX4 acknowledges ACCEPTED."""
        if not items and not count_zero:
            await self.clear_mission(mission_type)
            return
        count = self.mav.mission_count_encode(self.system_id, 1, len(items), mission_type)
        last: list[Any] = [count]
        seen = self.last_transfer = []

        def accept(m: Any) -> bool | None:
            if m.mission_type != mission_type or m.target_system not in (0, 255):
                return False
            seen.append(m.get_type())
            if m.get_type() == "MISSION_ACK":
                return True
            if not 0 <= m.seq < len(items):
                return False
            # PX4 asks with MISSION_REQUEST until it has seen an INT message from us, and
            # takes MISSION_ITEM_INT in answer: the INT form unless ``legacy``
            item = items[m.seq].replace(seq=m.seq)
            reply = item_message(self.mav, self.system_id, 1, item, legacy=legacy)
            last[0] = reply
            self.send(reply)
            return None  # progress

        async with (
            self._transfer,
            self.listen("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK") as inbox,
        ):
            ack = await self._exchange(inbox, lambda: self.send(last[0]), accept)
        if ack.type != ACCEPTED:
            raise MissionRefused(int(ack.type), f"upload of {len(items)} items")

    async def clear_mission(self, mission_type: int = 0) -> None:
        """MISSION_CLEAR_ALL; MissionRefused unless acknowledged ACCEPTED."""
        clear = self.mav.mission_clear_all_encode(self.system_id, 1, mission_type)
        async with self._transfer, self.listen("MISSION_ACK") as inbox:
            ack = await self._exchange(
                inbox, lambda: self.send(clear), lambda m: m.mission_type == mission_type
            )
        if ack.type != ACCEPTED:
            raise MissionRefused(int(ack.type), f"clear (mission type {mission_type})")

    async def download_mission(
        self, *, mission_type: int = 0, legacy: bool = False
    ) -> list[MissionItem]:
        """The mission as PX4 sends it (frames, flags and params untouched), asked for with
        MISSION_REQUEST_INT (``legacy``: MISSION_REQUEST)."""
        seen = self.last_transfer = []
        items: list[MissionItem] = []
        types = ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ITEM", "MISSION_ACK")
        async with self._transfer, self.listen(*types) as inbox:

            def ours(m: Any) -> bool:
                if m.mission_type != mission_type or m.target_system not in (0, 255):
                    return False
                seen.append(m.get_type())
                return True

            def count(m: Any) -> bool:
                return ours(m) and m.get_type() in ("MISSION_COUNT", "MISSION_ACK")

            def item(m: Any) -> bool:
                if not ours(m) or m.get_type() == "MISSION_COUNT":
                    return False
                return m.get_type() == "MISSION_ACK" or bool(m.seq == len(items))

            request_list = self.mav.mission_request_list_encode(self.system_id, 1, mission_type)
            reply = await self._exchange(inbox, lambda: self.send(request_list), count)
            if reply.get_type() == "MISSION_ACK":
                raise MissionRefused(int(reply.type), "download")
            encode = (
                self.mav.mission_request_encode if legacy else self.mav.mission_request_int_encode
            )
            for seq in range(int(reply.count)):
                request = encode(self.system_id, 1, seq, mission_type)

                def send_request(request: Any = request) -> None:
                    self.send(request)

                message = await self._exchange(inbox, send_request, item)
                if message.get_type() == "MISSION_ACK":
                    raise MissionRefused(int(message.type), f"download of item {seq}")
                items.append(item_from(message, legacy=message.get_type() == "MISSION_ITEM"))
            self.send(self.mav.mission_ack_encode(self.system_id, 1, ACCEPTED, mission_type))
        return items

    async def set_current(self, seq: int, timeout_s: float = 5.0) -> None:
        """MISSION_SET_CURRENT, confirmed by MISSION_CURRENT."""
        message = self.mav.mission_set_current_encode(self.system_id, 1, seq)
        async with self.listen("MISSION_CURRENT") as inbox:
            await self._exchange(inbox, lambda: self.send(message), lambda m: m.seq == seq)
