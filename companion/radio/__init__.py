"""The LoRa-like radio link: frames, airtime and regulation, reliable messages, transports.

Pure core: :mod:`.airtime` (time on air, profiles, duty-cycle budget), :mod:`.frames`
(header, CRC, strict decoding), :mod:`.reassembly` (receiver), :mod:`.arq` (sender).
With I/O: :mod:`.endpoint` (asyncio driver) over a :mod:`.transport`: :mod:`.serial_port` (a
LoRa modem on a UART) or :mod:`.udp` (a channel shared by processes, :mod:`companion.sim`).
"""

from companion.radio.airtime import PROFILES, LinkProfile, profile
from companion.radio.arq import LinkError, LinkTimeout, MessageTooLarge, PeerAborted
from companion.radio.clock import Clock
from companion.radio.config import LinkConfig
from companion.radio.endpoint import LinkEndpoint
from companion.radio.frames import AbortCode
from companion.radio.stats import LinkStats

__all__ = [
    "PROFILES",
    "AbortCode",
    "Clock",
    "LinkConfig",
    "LinkEndpoint",
    "LinkError",
    "LinkProfile",
    "LinkStats",
    "LinkTimeout",
    "MessageTooLarge",
    "PeerAborted",
    "profile",
]
