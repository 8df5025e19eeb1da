"""The vehicle's mission: items and mission files, the autopilot (MAVSDK) and what PX4 and
ArduPilot do with items, the flown path, the flight model and schedule, altitude levels, and
the edits (raises, holds) the companion uploads.
"""
