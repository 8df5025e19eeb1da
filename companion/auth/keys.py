"""Signing keys of drones and operators (Ed25519), their fingerprints, and key files.

Why Ed25519 (RFC 8032) from pyca/cryptography: deterministic signatures (no per-signature
randomness to get wrong on a small computer), 32-byte keys and 64-byte signatures, about
30 us to sign and 100 us to verify here, and the same well-kept library gives the session's
X25519, HKDF and ChaCha20-Poly1305 (:mod:`companion.auth.session`), so the radio's security
rests on one audited implementation.  (BIP-340 Schnorr through coincurve would have saved
the dependency for signatures only, not for the AEAD.)

Files: a private key is PKCS#8 PEM (written with mode 0600 by :mod:`companion.cli.keys`); a
public key is SubjectPublicKeyInfo PEM (both read by ``openssl pkey``).  A public key may also be
given as 64 hex digits (a trust store entry in a config file).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from cryptography.exceptions import InvalidSignature, UnsupportedAlgorithm
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from companion.errors import CompanionError

PUBLIC_SIZE = 32
SIGNATURE_SIZE = 64
FINGERPRINT_SIZE = 8


class KeyFileError(CompanionError):
    """A key file cannot be read or written; says which file and why."""


def fingerprint(public: bytes) -> bytes:
    """8 bytes naming a public key (certificates name operators by it; logs show it)."""
    return hashlib.sha256(b"pdc/key/v1" + public).digest()[:FINGERPRINT_SIZE]


@dataclass(frozen=True, slots=True)
class PublicKey:
    """An Ed25519 public key (32 raw bytes)."""

    raw: bytes

    def __post_init__(self) -> None:
        if len(self.raw) != PUBLIC_SIZE:
            raise ValueError(f"an Ed25519 public key has {PUBLIC_SIZE} bytes, not {len(self.raw)}")

    @property
    def fingerprint(self) -> bytes:
        return fingerprint(self.raw)

    def verify(self, signature: bytes, data: bytes) -> bool:
        """True if ``signature`` is this key's signature of ``data`` (never raises)."""
        if len(signature) != SIGNATURE_SIZE:
            return False
        try:
            Ed25519PublicKey.from_public_bytes(self.raw).verify(signature, data)
        except (InvalidSignature, ValueError):
            return False
        return True

    @classmethod
    def parse(cls, text: str) -> PublicKey:
        """64 hex digits."""
        try:
            raw = bytes.fromhex(text.strip())
        except ValueError:
            raise ValueError("a public key is 64 hex digits") from None
        return cls(raw)


class SigningKey:
    """An Ed25519 private key."""

    def __init__(self, key: Ed25519PrivateKey) -> None:
        self._key = key
        self.public = PublicKey(
            key.public_key().public_bytes(
                serialization.Encoding.Raw, serialization.PublicFormat.Raw
            )
        )

    @classmethod
    def generate(cls) -> SigningKey:
        return cls(Ed25519PrivateKey.generate())  # os.urandom inside OpenSSL

    def sign(self, data: bytes) -> bytes:
        return self._key.sign(data)

    @property
    def fingerprint(self) -> bytes:
        return self.public.fingerprint

    def pem(self) -> bytes:
        return self._key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )


def public_pem(key: PublicKey) -> bytes:
    """A public key as SubjectPublicKeyInfo PEM (what a ``.pub`` file holds)."""
    return Ed25519PublicKey.from_public_bytes(key.raw).public_bytes(
        serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo
    )


def _read(path: Path) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise KeyFileError(f"{path}: {exc.strerror or exc}") from None


def read_private_key(path: Path) -> SigningKey:
    data = _read(path)
    try:
        key = serialization.load_pem_private_key(data, password=None)
    except (ValueError, TypeError, UnsupportedAlgorithm):
        raise KeyFileError(f"{path}: not an unencrypted PEM private key") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise KeyFileError(f"{path}: not an Ed25519 key")
    return SigningKey(key)


def read_public_key(path: Path) -> PublicKey:
    """A PEM public key file, or a file holding 64 hex digits."""
    data = _read(path)
    if b"-----BEGIN" not in data:
        try:
            return PublicKey.parse(data.decode("ascii"))
        except (UnicodeDecodeError, ValueError):
            raise KeyFileError(f"{path}: neither a PEM public key nor 64 hex digits") from None
    try:
        key = serialization.load_pem_public_key(data)
    except (ValueError, UnsupportedAlgorithm):
        raise KeyFileError(f"{path}: not a PEM public key") from None
    if not isinstance(key, Ed25519PublicKey):
        raise KeyFileError(f"{path}: not an Ed25519 key")
    return PublicKey(key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw))
