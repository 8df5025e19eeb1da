"""The companion's error root.

Every error the companion raises on purpose is a :class:`CompanionError` (the protocol's are
:class:`protocol.errors.ProtocolError`): the command line reports either as one line and exit 2,
a run that ends on either as failed; anything else is a bug (exit 3, "internal" in the log).
"""

from __future__ import annotations


class CompanionError(Exception):
    """Base class of every error the companion raises on purpose."""
