"""The flight companion: the asyncio process beside the autopilot.

Everything with I/O lives here; the cryptography and the protocol state machines are in
:mod:`protocol`.  :mod:`companion.radio` is the LoRa-like radio link, :mod:`companion.runs.exchange`
runs the protocol over it, :mod:`companion.over_link` measures that (``compare --link``,
``bench link``).
"""
