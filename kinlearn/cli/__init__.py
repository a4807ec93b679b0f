"""The ``kinlearn`` command line: ``main`` builds the parser; each module adds its subcommands."""
