"""The ``drake-hybrid`` command (also ``python -m drake_hybrid``).

``drake-hybrid --help`` (``-h``) is answered from ``drake_hybrid.commands`` alone, with the standard
library only. Everything else goes to ``drake_hybrid.cli.main``, which is light to import too (the
standard library, numpy and the tasks' options): a command's --help prints at once, and a command
prints its first stage line ("drake-hybrid simulate: loading Drake, numba and matplotlib ... 2.1 s",
on standard error; nothing with --quiet) before it loads what it uses. tests/test_cli_help.py checks
that neither imports pydrake, numba, matplotlib or Dask.
"""

import importlib
import sys

from drake_hybrid.commands import COMMAND_HELP, top_level_help

COMMANDS = tuple(COMMAND_HELP)     # drake_hybrid.cli.make_parser's (tested)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["-h"], ["--help"]):          # the top-level help: text only, nothing to load
        sys.stdout.write(top_level_help())
        return 0
    return importlib.import_module("drake_hybrid.cli").main(argv, loading_line=True)


if __name__ == "__main__":
    sys.exit(main())
