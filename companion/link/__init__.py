"""The LoRa-like radio link: frames, airtime and regulation, reliable messages, transports.

Pure core: :mod:`.airtime` (time on air, profiles, duty-cycle budget), :mod:`.frames`
(header, CRC, strict decoding), :mod:`.reassembly` (receiver), :mod:`.arq` (sender).
With I/O: :mod:`.endpoint` (asyncio driver), :mod:`.medium` (simulated channel),
:mod:`.udp` (one channel shared by processes), :mod:`.serial_port` (a LoRa modem on a UART).
"""

from .airtime import PROFILES, LinkProfile, profile
from .arq import LinkError, LinkTimeout, MessageTooLarge, PeerAborted
from .clock import Clock, SimulationStalled, VirtualTimeLoop, run_simulated
from .config import LinkConfig
from .endpoint import LinkEndpoint
from .frames import AbortCode
from .medium import Channel, Impairments, SimMedium
from .stats import LinkStats

__all__ = [
    "PROFILES",
    "AbortCode",
    "Channel",
    "Clock",
    "Impairments",
    "LinkConfig",
    "LinkEndpoint",
    "LinkError",
    "LinkProfile",
    "LinkStats",
    "LinkTimeout",
    "MessageTooLarge",
    "PeerAborted",
    "SimMedium",
    "SimulationStalled",
    "VirtualTimeLoop",
    "profile",
    "run_simulated",
]
