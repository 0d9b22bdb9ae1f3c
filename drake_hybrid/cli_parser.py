"""The ``drake-hybrid`` command line's parser: every command, its options and their help (``build_parser``;
``drake_hybrid.cli.make_parser`` gives it the commands' functions). Light to import, as the command line is:
the standard library, the top-level parser of ``drake_hybrid.commands``, the control modes and the built-in
tasks' options (``tasks.task_options``), so that every ``--help`` answers at once. The help is the users':
docs/reference/command_line.md's synopsis mirrors it (tests/test_cli_help.py)."""

import argparse

from drake_hybrid.commands import COMMAND_HELP, top_level_parser
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.tasks.task_options import BUILT_IN_OPTIONS, built_in_option_help, is_task_file


def task_argument(value):
    """The TASK argument: a task's name, or a task file (FILE.yaml, tasks/task_file.py)."""
    if is_task_file(value) or value in BUILT_IN_OPTIONS:
        return value
    raise argparse.ArgumentTypeError(f"invalid choice: '{value}' (choose from {', '.join(sorted(BUILT_IN_OPTIONS))}, "
                                     "or give a task file FILE.yaml)")


def task_options_epilog():
    """The valid --option keys of every built-in task (from its typed Options, ``tasks.task_options``)."""
    lines = ["task options (--option KEY=VALUE, repeatable):"]
    for name in BUILT_IN_OPTIONS:
        entries = built_in_option_help(name)
        lines.append(f"  {name}:" + (" none" if not entries else ""))
        lines += [f"    {entry}" for entry in entries]
    return "\n".join(lines)


HARDWARE_TASKS = {"panda-drum": "panda_drum_task", "panda-table": "panda_table_task"}   # hardware.panda's
HARDWARE_DEFAULTS = {"hil": (2.0, 0.05), "timing": (10.0, 0.02), "run": (10.0, 0.02)}   # --duration s, --speed m/s


def build_parser(commands):
    """The ``drake-hybrid`` parser: every command with its options (``args.func``: the command's function
    in ``commands``, a dict by command name: simulate, analyze, sweep, hardware, tasks)."""
    parser, sub = top_level_parser()
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--traceback", action="store_true",
                        help="show the full Python traceback of an error (also DRAKE_HYBRID_TRACEBACK=1)")
    modes = [m.value for m in ControlMode]
    epilog = task_options_epilog()
    task_help = (", ".join(sorted(BUILT_IN_OPTIONS))
                 + ", or a task file FILE.yaml (a whole task in one file: models/tasks/)")
    simulate = sub.add_parser("simulate", parents=[common],
                              help=COMMAND_HELP["simulate"],
                              description="Simulate a task; writes log.npz, summary.json, config.yaml and the "
                                          "plots to --out.",
                              epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    simulate.add_argument("task", type=task_argument, metavar="TASK", help=task_help)
    simulate.add_argument("--duration", type=float, metavar="S", help="simulated time (s)")
    simulate.add_argument("--out", metavar="DIR", help="output directory (default ./runs/<task>)")
    simulate.add_argument("--mode", choices=modes, help="control law (default: the task's)")
    simulate.add_argument("--config", metavar="FILE.yaml", help="YAML scenario config (on top of the task's defaults)")
    simulate.add_argument("--option", action="append", metavar="KEY=VALUE",
                          help="a task option, repeatable; the keys of each task are listed below")
    simulate.add_argument("--html", metavar="FILE", help="also write a self-contained Meshcat animation to this file")
    simulate.add_argument("--no-progress", action="store_true", help="no progress bar")
    simulate.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    simulate.add_argument("--quiet", action="store_true",
                          help="no setup stages and no progress bar on stderr (for scripts); results still printed")
    simulate.set_defaults(func=commands["simulate"])
    analyze = sub.add_parser("analyze", parents=[common],
                             help=COMMAND_HELP["analyze"],
                             description="Linearize the closed loop at a contact equilibrium and compare its "
                                         "eigenvalues with the ones the gains design.",
                             epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    analyze.add_argument("task", type=task_argument, metavar="TASK", help=task_help)
    analyze.add_argument("--mode", choices=modes, help="control law (default: the task's)")
    analyze.add_argument("--config", metavar="FILE.yaml", help="YAML scenario config (on top of the task's defaults)")
    analyze.add_argument("--option", action="append", metavar="KEY=VALUE",
                         help="a task option, repeatable; the keys of each task are listed below")
    analyze.add_argument("--json", metavar="FILE", help="write the eigenvalues to this JSON file")
    analyze.add_argument("--plot", metavar="FILE.png",
                         help="write the eigenvalue figure (designed vs. linearized) to this PNG")
    analyze.add_argument("--tolerance", type=float, default=0.05, metavar="REL",
                         help="relative tolerance of the match, in (0, 1] (default 0.05: within 5 %%)")
    analyze.add_argument("--strict", action="store_true",
                         help="exit 1 on any miss, also where it is predicted (a designed eigenvalue the task "
                              "predicts shifted, an unstable mode its diagnosis predicts; default: exit 0 when "
                              "every miss is within --tolerance of its prediction)")
    analyze.add_argument("--quiet", action="store_true", help="no setup stages on stderr (for scripts)")
    analyze.set_defaults(func=commands["analyze"])
    sweep = sub.add_parser("sweep", parents=[common],
                           help=COMMAND_HELP["sweep"],
                           description="Evaluate a grid or Monte Carlo sample of config fields: per point a short "
                                       "simulation, two linearizations and the verdicts, appended to "
                                       "DIR/results.csv (docs/stability.md).")
    sweep.add_argument("task", type=task_argument, metavar="TASK", help=task_help)
    sweep.add_argument("--grid", required=True, metavar="SPEC.yaml",
                       help="sweep spec: the config fields to vary and how (grid or random), the map to plot; "
                            "format in docs/stability.md")
    sweep.add_argument("--out", metavar="DIR", help="output directory (default ./runs/sweep-<task>)")
    sweep.add_argument("--scheduler", metavar="ADDRESS",
                       help="address of an existing Dask scheduler (e.g. tcp://host:8786)")
    sweep.add_argument("--workers", type=int, default=2, metavar="N",
                       help="worker processes of the local Dask cluster (default 2; 0 = serial, no Dask)")
    sweep.add_argument("--resume", action="store_true", help="continue the table in --out: run only missing points")
    sweep.add_argument("--retry-failed", action="store_true", help="with --resume, also re-run points with errors")
    sweep.add_argument("--plot", action="store_true", help="write the stability map / histograms (the spec's map:)")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")
    sweep.set_defaults(func=commands["sweep"])
    hardware = sub.add_parser(
        "hardware", help=COMMAND_HELP["hardware"],
        description="The controller over Drake's Panda LCM messages (docs/hardware.md). Each mode prints a short "
                    "summary; --json FILE also writes its figures. A stop by the watchdog is a fault: printed as "
                    "one and exit 1.")
    hardware_modes = hardware.add_subparsers(dest="mode", required=True, metavar="MODE",
                                            help="what to run; drake-hybrid hardware MODE --help gives its options")
    for mode, summary, description in [
            ("hil", "lock-step hardware-in-the-loop run over memq:// vs the directly wired loop",
             "Run the task twice: controller and simulated Panda as two diagrams exchanging only LCM messages "
             "over memq:// in lock step, and directly wired; print both runs' velocity and force errors after "
             "five design time constants and their difference."),
            ("timing", "real-time run at 1 kHz over memq:// (replayed robot): cost, jitter, deadline misses",
             "Record what the robot side sends in a lock-step run, replay it at wall-clock rate to a fresh "
             "controller side over memq:// in this process; print the real-time settings applied, the controller's "
             "cost per tick in all and by part, the period jitter, the deadline misses by cause and what to do "
             "about each."),
            ("run", "the controller side against a real driver at --lcm-url",
             "Wait up to --wait seconds for the driver's first status at --lcm-url, then tick on each status for "
             "--duration seconds, sending torque commands; exit 1 without commanding if no valid status came. "
             "Before a first run on an arm read docs/hardware.md.")]:
        parser_ = hardware_modes.add_parser(mode, parents=[common], help=summary, description=description)
        parser_.add_argument("--task", choices=sorted(HARDWARE_TASKS), default="panda-drum",
                             help="the Panda task (default panda-drum)")
        parser_.add_argument("--duration", type=float, metavar="SECONDS",
                             help=f"seconds of control, > 0 (default {HARDWARE_DEFAULTS[mode][0]:g})")
        if mode == "timing":
            parser_.add_argument("--lcm-url", default="memq://drake_hybrid", metavar="URL",
                                 help="in-process LCM URL, memq:// only (default memq://drake_hybrid)")
        elif mode == "run":
            parser_.add_argument("--lcm-url", required=True, metavar="URL",
                                 help="the driver's LCM URL, e.g. udpm://239.255.76.67:7667?ttl=0")
            parser_.add_argument("--wait", type=float, default=5.0, metavar="SECONDS",
                                 help="seconds to wait for the first status, >= 0 (default 5)")
        parser_.add_argument("--wrench-source", choices=["force_torque", "external_torque"], default="force_torque",
                             help="the measured wrench: the wrist F/T sensor's channel or the driver's external "
                                  "joint torques (default force_torque)")
        parser_.add_argument("--speed", type=float, metavar="M/S",
                             help=f"commanded speed along the surface in m/s, any finite number (negative: the "
                                  f"other way; default {HARDWARE_DEFAULTS[mode][1]:g})")
        if mode != "hil":
            parser_.add_argument("--no-realtime", action="store_true",
                                 help="leave the scheduler, the core and the garbage collector as they are (default: "
                                      "SCHED_FIFO priority 50, pinned to the last core, collector paused, each where "
                                      "the process may; the summary says what was applied)")
        parser_.add_argument("--json", metavar="FILE", help="also write the figures to this JSON file")
        parser_.set_defaults(func=commands["hardware"])
    tasks = sub.add_parser("tasks", parents=[common], help=COMMAND_HELP["tasks"],
                           description="List the tasks and what each one does.")
    tasks.set_defaults(func=commands["tasks"])
    return parser
