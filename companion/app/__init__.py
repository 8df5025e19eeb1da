"""The companion itself: its runtime and shared core, settings (config files and tables), the
state kept on disk, and logs.
"""
