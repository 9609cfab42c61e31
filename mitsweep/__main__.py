from mitsweep.cli.main import entry

entry()
