"""The command line's top level, with the standard library only: the description ``drake-hybrid
--help`` prints, each command's one-line help and the top-level parser. ``drake_hybrid.cli`` adds each
command's options to it; the entry point (``drake_hybrid.__main__``) answers ``drake-hybrid --help``
from it alone, without loading Drake, numba, matplotlib and Dask (a few seconds) for a page of text.
tests/test_cli_help.py checks that both print the same help.
"""

import argparse

DESCRIPTION = """drake-hybrid: hybrid velocity/force control (Li & Sastry 1987) as Drake systems.

commands:
  drake-hybrid simulate TASK    simulate a task; writes log.npz, summary.json, config.yaml and plots
  drake-hybrid analyze TASK     linearize the closed loop; designed vs. linearized eigenvalues
                                (TASK: a task's name, or a task file FILE.yaml: docs/task_files.md)
  drake-hybrid sweep TASK --grid SPEC.yaml
                                stability map / Monte Carlo sweep over config fields (Dask)
  drake-hybrid tasks            list the tasks
  drake-hybrid hardware hil|timing|run
                                the controller over Drake's Panda LCM messages (memq:// in tests)

"drake-hybrid COMMAND --help" gives each command's options.

Bad input (a config field, a flag, a file) prints one line naming it and exits 2; a run that
stops early (sensor fault, an error inside the simulation, Ctrl-C) writes what it logged up to
the stop, prints why and exits 1. --traceback (or DRAKE_HYBRID_TRACEBACK=1) shows the full
Python traceback instead. An error that is a bug of drake-hybrid's, not a mistake in your input,
prints its traceback and a line saying so, and exits 70.
"""

# Each command's line in the top-level help, in the parser's order.
COMMAND_HELP = {
    "simulate": "simulate a task (discrete plant at 1 kHz, the crank's at 2 kHz; 1 kHz controller)",
    "analyze": "linearize the closed loop; designed vs. linearized eigenvalues",
    "sweep": "stability map / Monte Carlo sweep over config fields (Dask)",
    "hardware": "the controller over Drake's Panda LCM messages (hil, timing, run)",
    "tasks": "list the tasks",
}


def top_level_parser():
    """(the ``drake-hybrid`` parser, its COMMAND subparsers action): no command added yet."""
    parser = argparse.ArgumentParser(prog="drake-hybrid", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    return parser, parser.add_subparsers(dest="command", required=True, metavar="COMMAND")


def top_level_help():
    """``drake-hybrid --help``'s text: the description and one line per command."""
    parser, sub = top_level_parser()
    for name, text in COMMAND_HELP.items():
        sub.add_parser(name, help=text)
    return parser.format_help()
