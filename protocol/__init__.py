"""Private drone deconfliction: the sans-IO cryptographic core.

Pure state machines and value types; no sockets, no asyncio, no clocks.  Start reading at
:mod:`protocol.intersection` (the path protocol and its two suites), then the sub-protocols it
composes: :mod:`protocol.compact.products`, :mod:`protocol.compact.millionaire` and
:mod:`protocol.compact.gmw` on the OT layer (:mod:`protocol.ot`) for the compact suite;
:mod:`protocol.paper.comparison` (Veugen) and
:mod:`protocol.paper.hegates` on :mod:`protocol.primitives.paillier` and
:mod:`protocol.primitives.dgk` for the paper suite.
"""

from protocol.errors import (
    InsecureParametersError,
    LocalProtocolError,
    ProtocolError,
    RemoteProtocolError,
)
from protocol.intersection import Alice, Bob
from protocol.messages import Suite
from protocol.paper.comparison import ComparisonAlice, ComparisonBob
from protocol.paper.keys import BobKeys
from protocol.primitives.dgk import DGKCiphertext, DGKPrivateKey, DGKPublicKey
from protocol.primitives.paillier import PaillierCiphertext, PaillierPrivateKey, PaillierPublicKey
from protocol.primitives.params import SecurityParameters
from protocol.run import Limits

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
