"""A LoRa modem on a UART (pyserial), for flying hardware.

The modem is used in *transparent* mode: bytes written to the UART go on the air, bytes
received come out of it.  Such modems (Ebyte E22/E32, RAK3172 in P2P mode with a transparent
firmware, ...) cut the byte stream into radio packets of their own, so link frames are
delimited on the UART with COBS (zero byte as separator): a frame split or merged by the modem
is reassembled, a damaged one fails its CRC and is dropped.  Settings are in ``docs/link.md``:
the modem's air parameters must match the link profile (its airtime accounting and duty-cycle
budget are computed here, not by the modem).
"""

from __future__ import annotations

import asyncio
from typing import Any

from companion.radio.airtime import PHY_MAX_FRAME
from companion.radio.clock import Clock
from companion.radio.transport import Receiver

MAX_ENCODED = PHY_MAX_FRAME + PHY_MAX_FRAME // 254 + 2


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the result contains no zero byte."""
    out = bytearray([0])
    code_at, code = 0, 1
    for byte in data:
        if byte:
            out.append(byte)
            code += 1
        if not byte or code == 0xFF:
            out[code_at] = code
            code_at, code = len(out), 1
            out.append(0)
    out[code_at] = code
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises ValueError on malformed input."""
    out = bytearray()
    i = 0
    while i < len(data):
        code = data[i]
        if code == 0 or i + code > len(data) or 0 in data[i + 1 : i + code]:
            raise ValueError("malformed COBS block")
        out += data[i + 1 : i + code]
        i += code
        if code != 0xFF and i < len(data):
            out.append(0)
    return bytes(out)


class SerialTransport:
    """Frames over a serial port; ``url`` as pyserial takes it (``/dev/ttyUSB0``, ...)."""

    def __init__(self, port: Any, clock: Clock | None = None) -> None:
        self.port = port
        self.clock = clock or Clock()
        self._receiver: Receiver | None = None
        self._buffer = bytearray()
        self.dropped = 0
        asyncio.get_running_loop().add_reader(port.fileno(), self._readable)

    @classmethod
    def open(cls, url: str, baudrate: int = 115200, clock: Clock | None = None) -> SerialTransport:
        import serial  # pyserial: imported here so the rest of the link needs no UART

        port = serial.serial_for_url(url, baudrate=baudrate, timeout=0, write_timeout=0)
        return cls(port, clock)

    def set_receiver(self, callback: Receiver) -> None:
        self._receiver = callback

    def _readable(self) -> None:
        chunk = self.port.read(4096)
        if not chunk:
            return
        self._buffer += chunk
        while b"\x00" in self._buffer:
            encoded, _, rest = self._buffer.partition(b"\x00")
            self._buffer = bytearray(rest)
            self._frame(bytes(encoded))
        if len(self._buffer) > MAX_ENCODED:  # no delimiter in sight: line noise
            self._buffer.clear()
            self.dropped += 1

    def _frame(self, encoded: bytes) -> None:
        if not encoded:
            return
        try:
            frame = cobs_decode(encoded)
        except ValueError:
            self.dropped += 1
            return
        if self._receiver is not None:
            self._receiver(frame)

    async def transmit(self, frame: bytes, airtime: float) -> None:
        data = b"\x00" + cobs_encode(frame) + b"\x00"
        written = 0
        while written < len(data):
            written += self.port.write(data[written:]) or 0
            if written < len(data):
                await asyncio.sleep(0.001)
        await self.clock.sleep(airtime)  # the modem is on the air for this long

    async def close(self) -> None:
        asyncio.get_running_loop().remove_reader(self.port.fileno())
        self.port.close()
