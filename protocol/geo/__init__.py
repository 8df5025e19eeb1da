"""Geometry on the integer grid: segments and paths, WGS84 and the tangent plane, the grid,
protected volumes (separation, altitude bands, time windows).
"""
