"""Who is around: beacons (the format), checking them (the registry), the peers they make, and
our own beacons out.
"""
