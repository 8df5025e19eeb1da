"""Fixed-width integer encoding and a strict reader for received bytes.

Every integer on the wire has a width fixed by public parameters (a Paillier ciphertext of a
2048-bit key is always 512 bytes), so message sizes never depend on secret values.  The
:class:`Reader` raises :class:`RemoteProtocolError` on any short read or trailing byte; nothing
else escapes it.
"""

from __future__ import annotations

from protocol.errors import LocalProtocolError, RemoteProtocolError


def int_to_fixed(value: int, width: int) -> bytes:
    """Big-endian unsigned encoding of ``value`` in exactly ``width`` bytes."""
    if value < 0 or value.bit_length() > 8 * width:
        raise LocalProtocolError(f"integer does not fit in {width} bytes")
    return int(value).to_bytes(width, "big")


def byte_width(modulus: int) -> int:
    """Bytes needed for any residue modulo ``modulus``."""
    return (int(modulus - 1).bit_length() + 7) // 8


class Reader:
    """Consumes a byte string field by field; any mismatch is the peer's fault."""

    __slots__ = ("_data", "_pos")

    def __init__(self, data: bytes) -> None:
        if not isinstance(data, bytes | bytearray | memoryview):
            raise RemoteProtocolError("expected bytes")
        self._data = bytes(data)
        self._pos = 0

    def take(self, n: int) -> bytes:
        """The next ``n`` bytes."""
        if n < 0 or self._pos + n > len(self._data):
            raise RemoteProtocolError(
                f"truncated input: wanted {n} bytes at offset {self._pos}, "
                f"have {len(self._data) - self._pos}"
            )
        chunk = self._data[self._pos : self._pos + n]
        self._pos += n
        return chunk

    def uint(self, width: int) -> int:
        """The next fixed-width big-endian unsigned integer."""
        return int.from_bytes(self.take(width), "big")

    def remaining(self) -> int:
        return len(self._data) - self._pos

    @property
    def offset(self) -> int:
        """Bytes consumed so far."""
        return self._pos

    def finish(self) -> None:
        """Require that everything was consumed."""
        if self._pos != len(self._data):
            raise RemoteProtocolError(f"{len(self._data) - self._pos} trailing bytes")
