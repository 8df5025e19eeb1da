"""What a link endpoint needs from a radio: a simulated channel, a UDP hub or a LoRa modem."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

Receiver = Callable[[bytes], None]


class Transport(Protocol):
    """What a link endpoint needs from a radio."""

    def set_receiver(self, callback: Receiver) -> None: ...

    async def transmit(self, frame: bytes, airtime: float) -> None:
        """Put one frame on the air; return when its transmission has ended."""

    async def close(self) -> None: ...
