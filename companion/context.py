"""What every component of one companion shares: its settings, its clock, the event record
and the task group its work runs in (:class:`companion.app.runtime.Companion` makes it)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import Any

from companion.events import EventKind, Payload
from companion.radio.clock import Clock
from companion.settings import CompanionSettings

Spawn = Callable[[Coroutine[Any, Any, None], str], "asyncio.Task[None]"]


@dataclass(frozen=True)
class Context:
    """``record(kind, payload)``: an event (logged, kept for reports); ``spawn(work, name)``:
    a task in the companion's task group whose failure is logged and recorded, never
    silent and never fatal to the rest."""

    settings: CompanionSettings
    clock: Clock
    record: Callable[[EventKind, Payload], None]
    spawn: Spawn
