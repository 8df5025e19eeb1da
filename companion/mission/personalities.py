"""What PX4 and ArduPilot do with mission items: one table for the product and the mock.

The product uses it to refuse an upload the autopilot would refuse (:meth:`Personality.
problems`, before anything is sent) and to verify a read-back by what the autopilot *means*
(:meth:`Personality.same_meaning`): the frame pairs 3/6, 0/5 and 10/11 are one altitude
reference, a parameter the autopilot does not keep reads back as 0, NaN and 0 are the same
"not set", and yaw is an angle (PX4 wraps it into [0, 360)).  The mock autopilot uses
:meth:`Personality.stored` to hand back exactly what the real one would.

PX4 rows were measured on PX4 v1.16.0 SITL (``docs/autopilot.md``); ArduPilot rows follow its
documentation and ``AP_Mission`` source (not measured here).
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from companion.mission.items import (
    FRAMES_AMSL,
    FRAMES_GLOBAL,
    FRAMES_RELATIVE,
    FRAMES_TERRAIN,
    KNOWN_FRAMES,
    NAV_LAND,
    NAV_LOITER_TIME,
    NAV_LOITER_TO_ALT,
    NAV_LOITER_TURNS,
    NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH,
    NAV_SPLINE_WAYPOINT,
    NAV_TAKEOFF,
    NAV_VTOL_LAND,
    NAV_VTOL_TAKEOFF,
    NAV_WAYPOINT,
    POSITIONAL_NAV,
    MissionError,
    MissionItem,
)

DO_JUMP, DO_CHANGE_SPEED = 177, 178
PARAMS = ("param1", "param2", "param3", "param4")
# commands whose param4 is a yaw angle in degrees
YAW_PARAM4 = frozenset(
    {NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LAND, NAV_TAKEOFF, NAV_VTOL_TAKEOFF, NAV_VTOL_LAND}
)


class Firmware(enum.Enum):
    PX4 = "px4"
    ARDUPILOT = "ardupilot"


class UnsupportedItem(MissionError):
    """The autopilot would refuse this mission (checked before any upload)."""


def _f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def frame_class(frame: int) -> int:
    """The altitude reference a frame stands for (the _INT twin is the same reference)."""
    for group in (FRAMES_AMSL, FRAMES_RELATIVE, FRAMES_TERRAIN):
        if frame in group:
            return min(group)
    return frame


class Param(enum.Enum):
    """What an autopilot does with one parameter of one command on upload."""

    DROPPED = "always 0"
    NAN_TO_ZERO = "NaN read back as 0"
    BOOLEAN = "0/1: above 0 is 1, else 0 (NaN 0)"
    INTEGER = "truncated to an integer (NaN 0)"
    UINT16 = "truncated to uint16, negatives wrap (NaN 0)"

    def apply(self, value: float) -> float:
        if self is Param.DROPPED:
            return 0.0
        if math.isnan(value):
            return 0.0
        if self is Param.BOOLEAN:
            return 1.0 if value > 0 else 0.0
        if self is Param.INTEGER:
            return float(math.trunc(value)) if math.isfinite(value) else value
        if self is Param.UINT16:
            return float(math.trunc(value) % 65536) if math.isfinite(value) else 0.0
        return value


class Refusal(enum.Enum):
    """The MAV_MISSION_RESULT an autopilot answers a refused item with."""

    COMMAND = 3  # MAV_MISSION_UNSUPPORTED
    FRAME = 2  # MAV_MISSION_UNSUPPORTED_FRAME


@dataclass(frozen=True)
class Personality:
    """One autopilot's handling of mission items."""

    firmware: Firmware
    frames: frozenset[int]  # frames it takes at all
    unsupported_commands: frozenset[int]
    # non-positional commands it refuses in a global frame (PX4: DO_JUMP in frame 3)
    refused_in_global: frozenset[int]
    positional_needs_global: bool  # a NAV item with a position in frame 2 (MISSION) is refused
    stored_frames: dict[int, int]  # frame uploaded -> frame read back
    params: dict[tuple[int, str], Param]  # (command, param) -> what the upload does to it
    wraps_yaw: bool  # yaw (param4) read back in [0, 360)
    home_is_item0: bool
    takeoff_needs_position: bool  # a TAKEOFF at 0,0 is the real 0,0

    @property
    def name(self) -> str:
        return "ArduPilot" if self.firmware is Firmware.ARDUPILOT else "PX4"

    def refusal(self, it: MissionItem) -> tuple[Refusal, str] | None:
        """Why the autopilot refuses this item (None: it takes it)."""
        if it.frame not in self.frames:
            hint = (
                " (above terrain: give it relative or AMSL altitudes)"
                if it.frame in FRAMES_TERRAIN
                else ""
            )
            return Refusal.FRAME, f"{self.name} refuses frame {it.frame}{hint}"
        if it.mission_type != 0:
            return None
        if it.command in self.unsupported_commands:
            return Refusal.COMMAND, f"{self.name} refuses command {it.command}"
        if it.command in self.refused_in_global and it.frame in FRAMES_GLOBAL:
            return Refusal.COMMAND, (
                f"{self.name} refuses command {it.command} in global frame {it.frame} "
                "(it takes it in frame 2, MISSION)"
            )
        if self.positional_needs_global and it.command in POSITIONAL_NAV:
            if it.frame not in FRAMES_GLOBAL:
                return Refusal.COMMAND, (
                    f"{self.name} refuses command {it.command} in frame {it.frame} "
                    "(a position needs a global frame)"
                )
        return None

    def problems(self, items: Sequence[MissionItem]) -> list[str]:
        """Why the autopilot would refuse ``items`` (empty: it would take them)."""
        out = []
        for it in items:
            why = self.refusal(it)
            if why is not None:
                out.append(f"item {it.seq}: {why[1]}")
        return out

    def start_problems(self, items: Sequence[MissionItem]) -> list[str]:
        """Why the autopilot would take ``items`` but refuse to fly them (PX4: a take-off
        at 0,0 is the real 0,0, "first waypoint far away from home")."""
        if not self.takeoff_needs_position:
            return []
        return [
            f"item {it.seq}: a take-off at latitude/longitude 0,0 is the real 0,0 to "
            f"{self.name} (give it the take-off position)"
            for it in items
            if it.command in (NAV_TAKEOFF, NAV_VTOL_TAKEOFF) and it.x == 0 and it.y == 0
        ]

    def check(self, items: Sequence[MissionItem]) -> None:
        problems = self.problems(items)
        if problems:
            raise UnsupportedItem("; ".join(problems))

    def stored(self, item: MissionItem) -> MissionItem:
        """The item as this autopilot reads it back after an upload."""
        changes: dict[str, float | int] = {"frame": self.stored_frames.get(item.frame, item.frame)}
        for name in PARAMS:
            rule = self.params.get((item.command, name))
            if rule is not None:
                changes[name] = rule.apply(getattr(item, name))
        yaw = item.param4
        if self.wraps_yaw and item.command in YAW_PARAM4 and math.isfinite(yaw):
            changes["param4"] = _f32(math.fmod(_f32(yaw), 360.0) % 360.0)
        return item.replace(**changes)

    def same_meaning(self, sent: MissionItem, held: MissionItem) -> bool:
        """Does ``held`` (read back) mean what ``sent`` asked for?  Commands, positions,
        altitudes (float32) and the altitude reference must match; parameters match what
        this autopilot makes of them on upload (:meth:`stored`), where NaN and 0 are both
        "not set" and yaw is an angle."""
        if (sent.command, sent.x, sent.y, sent.autocontinue, sent.mission_type) != (
            held.command,
            held.x,
            held.y,
            held.autocontinue,
            held.mission_type,
        ):
            return False
        if frame_class(sent.frame) != frame_class(held.frame) or _f32(sent.z) != _f32(held.z):
            return False
        want = self.stored(sent)
        for name in PARAMS:
            a, b = getattr(want, name), getattr(held, name)
            if _param_equal(a, b) or _param_equal(getattr(sent, name), b):
                continue
            if name == "param4" and sent.command in YAW_PARAM4 and _angle_equal(a, b):
                continue
            return False
        return True


def _param_equal(a: float, b: float) -> bool:
    unset = (math.isnan(a) or a == 0) and (math.isnan(b) or b == 0)
    return unset or _f32(a) == _f32(b)


def _angle_equal(a: float, b: float) -> bool:
    if not (math.isfinite(a) and math.isfinite(b)):
        return False
    d = abs(math.fmod(a - b, 360.0))
    return min(d, 360.0 - d) < 1e-3


_GLOBAL_AND_MISSION = FRAMES_AMSL | FRAMES_RELATIVE | {2}
PX4 = Personality(
    Firmware.PX4,
    frames=_GLOBAL_AND_MISSION,  # measured: 1, 10, 11 and 99 refused with UNSUPPORTED_FRAME
    unsupported_commands=frozenset({NAV_LOITER_TURNS, NAV_SPLINE_WAYPOINT}),
    refused_in_global=frozenset({NAV_RETURN_TO_LAUNCH, DO_JUMP, DO_CHANGE_SPEED}),
    positional_needs_global=True,
    stored_frames={0: 5, 3: 6},
    params={
        (NAV_WAYPOINT, "param3"): Param.DROPPED,
        **{(NAV_TAKEOFF, p): Param.DROPPED for p in ("param1", "param2", "param3")},
        (NAV_LAND, "param1"): Param.DROPPED,
        (NAV_LAND, "param2"): Param.UINT16,
        (NAV_LAND, "param3"): Param.DROPPED,
        (NAV_LOITER_TIME, "param2"): Param.BOOLEAN,
        (NAV_LOITER_TIME, "param4"): Param.BOOLEAN,
        (NAV_LOITER_UNLIM, "param1"): Param.DROPPED,
        (NAV_LOITER_UNLIM, "param2"): Param.DROPPED,
        (NAV_LOITER_TO_ALT, "param1"): Param.BOOLEAN,
        (NAV_LOITER_TO_ALT, "param3"): Param.DROPPED,
        (NAV_LOITER_TO_ALT, "param4"): Param.BOOLEAN,
        (DO_JUMP, "param1"): Param.INTEGER,
        (DO_JUMP, "param2"): Param.UINT16,
    },
    wraps_yaw=True,
    home_is_item0=False,
    takeoff_needs_position=True,
)

ARDUPILOT = Personality(
    Firmware.ARDUPILOT,
    frames=KNOWN_FRAMES,
    unsupported_commands=frozenset(),
    refused_in_global=frozenset(),
    positional_needs_global=False,
    stored_frames={5: 0, 6: 3, 11: 10},  # AP_Mission answers in the non-_INT frames
    # AP_Mission keeps a waypoint's delay (param1) only (Copter); the rest reads back as 0
    params={
        (NAV_WAYPOINT, "param2"): Param.DROPPED,
        (NAV_WAYPOINT, "param3"): Param.DROPPED,
        (NAV_WAYPOINT, "param4"): Param.DROPPED,
        **{(c, p): Param.NAN_TO_ZERO for c in (NAV_TAKEOFF, NAV_LAND) for p in PARAMS},
    },
    wraps_yaw=False,
    home_is_item0=True,
    takeoff_needs_position=False,
)


def personality(ardupilot: bool) -> Personality:
    return ARDUPILOT if ardupilot else PX4
