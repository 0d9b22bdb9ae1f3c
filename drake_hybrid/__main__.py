"""The ``drake-hybrid`` command (also ``python -m drake_hybrid``): its first line, then the command line.

Importing ``drake_hybrid.cli`` loads Drake, numba, matplotlib and Dask, a few seconds. This entry
point prints a stage line with that time first, on standard error (``drake-hybrid simulate: loading
Drake, numba, matplotlib and Dask ... 3.1 s``; nothing with ``--quiet`` or ``--help``, or for an
unknown command, which the parser then names), and hands over to ``drake_hybrid.cli.main``. It
imports only the standard library, ``core.progress`` and ``commands`` (the package's names load on
first use: ``drake_hybrid/__init__.py``); tests/test_cli_help.py checks that pydrake is imported after
the line. ``drake-hybrid --help`` (``-h``) is answered from ``drake_hybrid.commands`` alone, in a
fraction of a second; a command's help (``drake-hybrid simulate --help``) lists the tasks' options,
which needs the tasks, so it loads the rest.
"""

import importlib
import sys

from drake_hybrid.commands import COMMAND_HELP, top_level_help
from drake_hybrid.core.progress import Stages

COMMANDS = tuple(COMMAND_HELP)     # drake_hybrid.cli.make_parser's (tested)
SILENT = {"-h", "--help", "--quiet"}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv else None
    if command in ("-h", "--help"):               # the top-level help: text only, nothing to load
        sys.stdout.write(top_level_help())
        return 0
    stages = Stages(enabled=command in COMMANDS and not SILENT & set(argv))
    with stages(f"drake-hybrid {command}: loading Drake, numba, matplotlib and Dask"):
        cli = importlib.import_module("drake_hybrid.cli")
    return cli.main(argv)


if __name__ == "__main__":
    sys.exit(main())
