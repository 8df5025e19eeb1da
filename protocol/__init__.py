"""Private drone deconfliction: the sans-IO cryptographic core.

Pure state machines and value types; no sockets, no asyncio, no clocks.  Start reading at
:mod:`protocol.comparison` (Veugen's secure comparison), which is built on
:mod:`protocol.paillier`, :mod:`protocol.dgk` and :mod:`protocol.ecelgamal`.
"""

from .comparison import ComparisonAlice, ComparisonBob
from .dgk import DGKCiphertext, DGKPrivateKey, DGKPublicKey
from .ecelgamal import ECCiphertext, ECPrivateKey, ECPublicKey
from .errors import (
    InsecureParametersError,
    LocalProtocolError,
    ProtocolError,
    RemoteProtocolError,
)
from .gadgets import AND, OR, XOR, GateAlice, GateBob, OpenedShares
from .paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from .params import SecurityParameters

__all__ = [
    "AND",
    "OR",
    "XOR",
    "ComparisonAlice",
    "ComparisonBob",
    "DGKCiphertext",
    "DGKPrivateKey",
    "DGKPublicKey",
    "ECCiphertext",
    "ECPrivateKey",
    "ECPublicKey",
    "GateAlice",
    "GateBob",
    "InsecureParametersError",
    "LocalProtocolError",
    "OpenedShares",
    "PaillierCiphertext",
    "PaillierPrivateKey",
    "PaillierPublicKey",
    "ProtocolError",
    "RemoteProtocolError",
    "SecurityParameters",
]
