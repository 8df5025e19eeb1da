"""The flight companion: asyncio process beside the autopilot (radio link, MAVLink, sessions).

Everything with I/O lives here; the cryptography and protocol state machines are in
:mod:`protocol`.  Filled in by the companion issues.
"""
