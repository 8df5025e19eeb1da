"""Fixed-width bit fields packed into bytes, strictly decoded.

Field i of width w_i is written most significant bit first; the fields follow each other with
no gaps and the last byte is padded with zero bits.  Widths are public, so the length of a
packed message never depends on a secret; :func:`unpack` refuses a wrong length and non-zero
padding with :class:`RemoteProtocolError`.
"""

from __future__ import annotations

from collections.abc import Sequence

from protocol.errors import LocalProtocolError, RemoteProtocolError


def packed_size(widths: Sequence[int]) -> int:
    return (sum(widths) + 7) // 8


def pack(values: Sequence[int], widths: Sequence[int]) -> bytes:
    """Concatenate ``values[i]`` in ``widths[i]`` bits each."""
    if len(values) != len(widths):
        raise LocalProtocolError("one width per value")
    parts = []
    for value, width in zip(values, widths, strict=True):
        if value < 0 or value >> width:
            raise LocalProtocolError(f"value does not fit in {width} bits")
        parts.append(format(value, f"0{width}b") if width else "")
    bits = "".join(parts)
    total = len(bits)
    size = (total + 7) // 8
    if not size:
        return b""
    return (int(bits, 2) << (8 * size - total)).to_bytes(size, "big")


def unpack(data: bytes, widths: Sequence[int]) -> list[int]:
    """The inverse of :func:`pack`; the peer's fault if ``data`` does not fit ``widths``."""
    total = sum(widths)
    size = (total + 7) // 8
    if len(data) != size:
        raise RemoteProtocolError(f"bit field block of {len(data)} bytes, expected {size}")
    if not size:
        return [0] * len(widths)
    number = int.from_bytes(data, "big")
    if number & ((1 << (8 * size - total)) - 1):
        raise RemoteProtocolError("padding bits must be zero")
    bits = format(number >> (8 * size - total), f"0{total}b") if total else ""
    out = []
    position = 0
    for width in widths:
        out.append(int(bits[position : position + width], 2) if width else 0)
        position += width
    return out


def pack_bits(bits: Sequence[int]) -> bytes:
    return pack(bits, [1] * len(bits))


def unpack_bits(data: bytes, count: int) -> list[int]:
    return unpack(data, [1] * count)
