"""Private drone deconfliction: the sans-IO cryptographic core.

Pure state machines and value types; no sockets, no asyncio, no clocks.  Start reading at
:mod:`protocol.intersection` (the path protocol and its two suites), then the sub-protocols it
composes: :mod:`protocol.products`, :mod:`protocol.millionaire` and :mod:`protocol.gmw` on the
OT layer (:mod:`protocol.ot`) for the compact suite; :mod:`protocol.comparison` (Veugen) and
:mod:`protocol.hegates` on :mod:`protocol.paillier` and :mod:`protocol.dgk` for the paper suite.
"""

from .comparison import ComparisonAlice, ComparisonBob
from .dgk import DGKCiphertext, DGKPrivateKey, DGKPublicKey
from .errors import (
    InsecureParametersError,
    LocalProtocolError,
    ProtocolError,
    RemoteProtocolError,
)
from .intersection import Alice, Bob, BobKeys, Limits
from .paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from .params import SecurityParameters
from .wire import Suite

__all__ = [
    "Alice",
    "Bob",
    "BobKeys",
    "ComparisonAlice",
    "ComparisonBob",
    "DGKCiphertext",
    "DGKPrivateKey",
    "DGKPublicKey",
    "InsecureParametersError",
    "Limits",
    "LocalProtocolError",
    "PaillierCiphertext",
    "PaillierPrivateKey",
    "PaillierPublicKey",
    "ProtocolError",
    "RemoteProtocolError",
    "SecurityParameters",
    "Suite",
]
