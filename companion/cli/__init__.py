"""The command line: `drone-deconflict` and its subcommands (both rooms: product and simulation)."""
