"""The simulation room: what tests, replays and demos fly instead of real drones.

Mock autopilots that speak MAVLink like PX4 and ArduPilot (``mock_autopilot``, ``mock_links``,
``mock_missions``), PX4 SITL vehicles (``px4``), and scripted replays (``scenario`` ->
``replay`` -> ``report``, ``plot``, ``export``; ``fleet`` and ``vehicles`` behind them).  The
product's modules (the rest of :mod:`companion`) never import anything from here.
"""
