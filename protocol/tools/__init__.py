"""The protocol's tools, apart from its sans-IO core: the command line and its shared plumbing
(``cli``), the comparison of path files (``compare``, ``formats``), benchmarks (``bench``,
``bench_paths``), the two-drone demo (``demo``) and the in-memory loopback that drives both
parties' state machines for them (``loopback``).  The core never imports from here.
"""
