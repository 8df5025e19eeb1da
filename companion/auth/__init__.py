"""Who is on the radio: drone identities, operator certificates, the trust store, signed
beacons' keys and authenticated runs.

Pure modules (no sockets, no asyncio): :mod:`.keys` (Ed25519 keys, fingerprints, key files),
:mod:`.certificate` (an operator vouches for a drone's key and node id), :mod:`.trust` (the
operators we deconflict with, and their limits), :mod:`.session` (the signed key exchange
and ChaCha20-Poly1305 on every protocol message).  ``docs/security.md`` says what each one
stops.
"""

from companion.auth.certificate import Certificate, CertificateError
from companion.auth.keys import KeyFileError, PublicKey, SigningKey
from companion.auth.session import (
    AuthenticationError,
    Identity,
    Initiator,
    Refusal,
    Responder,
    Route,
)
from companion.auth.trust import Operator, TrustStore, UnknownPeers, Untrusted, UntrustedPeer

__all__ = [
    "AuthenticationError",
    "Certificate",
    "CertificateError",
    "Identity",
    "Initiator",
    "KeyFileError",
    "Operator",
    "PublicKey",
    "Refusal",
    "Responder",
    "Route",
    "SigningKey",
    "TrustStore",
    "UnknownPeers",
    "Untrusted",
    "UntrustedPeer",
]
