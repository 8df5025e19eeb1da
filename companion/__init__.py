"""The flight companion: the asyncio process beside the autopilot.

Everything with I/O lives here; the cryptography and the protocol state machines are in
:mod:`protocol`.  The product: :mod:`companion.mission` (the vehicle's mission, its flown path
and schedule, edits), :mod:`companion.neighbours` (beacons, peers), :mod:`companion.runs` (runs
as Alice and as Bob over the radio, budget, fail-safe), :mod:`companion.radio` (the LoRa-like
link), :mod:`companion.auth` (keys, certificates, sessions) and :mod:`companion.app` (the
companion itself, its settings and state); :mod:`companion.cli` is the command line and
:mod:`companion.sim` the simulation it is tested in (docs/architecture.md).
"""
