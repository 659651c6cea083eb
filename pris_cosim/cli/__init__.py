"""The `pris-cosim` command line: the main parser and built-in commands, input checks, the simulate/build-fmu and lab commands.

:func:`main` is the command's entry point (:mod:`pris_cosim.cli.commands`).
"""

from pris_cosim.cli.commands import main

__all__ = ["main"]
