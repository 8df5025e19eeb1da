"""Error types of the protocol package.

Like h11, errors say whose fault they are:

* :class:`RemoteProtocolError` -- something that arrived from the peer (or the radio, or a file)
  is malformed, out of range, not a group element or out of order.  This is the *one* error type
  that decoding and state machines raise for bad input; nothing else escapes them.
* :class:`LocalProtocolError` -- we were asked to do something illegal (send a ciphertext that was
  not re-randomised, step a state machine out of order, use unsafe parameters).
"""

from __future__ import annotations


class ProtocolError(Exception):
    """Base class of every error this package raises on purpose."""


class RemoteProtocolError(ProtocolError):
    """The peer sent something that is not a valid message at this point."""


class LocalProtocolError(ProtocolError):
    """The local caller misused the API."""


class InsecureParametersError(LocalProtocolError):
    """Parameters below 112-bit security were requested without the test-only opt-in."""


class InputRangeError(LocalProtocolError):
    """A local input (coordinate, path length, grid parameter) is outside what is supported."""


class UnknownSetupError(RemoteProtocolError):
    """The peer's hello names an OT setup this party does not hold (it restarted, or dropped
    it): the peer should start a fresh one."""


class ConsistencyError(RemoteProtocolError):
    """The peer's OT extension fails the consistency check (:mod:`protocol.ot.check`): it
    deviated from the protocol, or the OT setup is corrupt.  The run ends and the setup must be
    dropped: its Delta may have been probed."""


class UntrustedKeysError(LocalProtocolError):
    """The paper suite was asked to run with a peer whose keys nobody vouched for: Alice cannot
    check the range of Bob's Paillier plaintexts nor his DGK key (docs/security.md, D3)."""
