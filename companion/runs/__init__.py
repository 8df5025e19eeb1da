"""Comparisons over the radio: runs as Alice and answers as Bob, the exchange of their messages
on the link, the radio's turns, the run budget, the fail-safe's estimates, progress reports.
"""
