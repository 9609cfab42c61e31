"""The ``mitsweep`` command-line program (argparse subcommands, each ``main(argv) -> int``)."""
