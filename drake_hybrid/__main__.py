"""The ``drake-hybrid`` command (also ``python -m drake_hybrid``): its first line, then the command line.

Importing ``drake_hybrid.cli`` loads Drake, numba, matplotlib and Dask, a few seconds. This entry
point prints a stage line with that time first, on standard error (``drake-hybrid simulate: loading
Drake, numba, matplotlib and Dask ... 3.1 s``; nothing with ``--quiet`` or ``--help``, or for an
unknown command, which the parser then names), and hands over to ``drake_hybrid.cli.main``. It
imports only the standard library and ``core.progress`` (the package's names load on first use:
``drake_hybrid/__init__.py``); tests/test_cli_help.py checks that pydrake is imported after the line.
"""

import importlib
import sys

from drake_hybrid.core.progress import Stages

COMMANDS = ("simulate", "analyze", "sweep", "hardware", "tasks")     # drake_hybrid.cli.make_parser's (tested)
SILENT = {"-h", "--help", "--quiet"}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv else None
    stages = Stages(enabled=command in COMMANDS and not SILENT & set(argv))
    with stages(f"drake-hybrid {command}: loading Drake, numba, matplotlib and Dask"):
        cli = importlib.import_module("drake_hybrid.cli")
    return cli.main(argv)


if __name__ == "__main__":
    sys.exit(main())
