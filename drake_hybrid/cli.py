"""The ``drake-hybrid`` command line: one function per command and ``main`` (the entry point,
``drake_hybrid.__main__``, imports this module after its first line); the parser, every command's
options and help, is ``drake_hybrid.cli_parser``'s. ``DESCRIPTION`` (from ``drake_hybrid.commands``) is
the top-level ``--help`` text, for users; this docstring is for readers of the source and is not printed
(tests/test_cli_help.py checks both, and the help against the README's synopsis).

A command parses its arguments, calls the package and prints what ``drake_hybrid.report`` says about
the result: the verdicts (``analyze``'s exit code), the ``--json`` payloads and the text are the report's,
which a notebook or a test can call too. ``main`` turns the package's own errors (``DrakeHybridError``:
a config field, a flag, a file) and a missing file into one line and exit code 2, and an error that is
a bug of the package's (a ``TypeError``, ``KeyError``, ...) into its traceback, a line saying so and
exit code 70 (``INTERNAL_ERROR``), never into the user's mistake.

Each command loads what it uses when it runs, under its first stage line ("drake-hybrid simulate:
loading Drake, numba and matplotlib ... 2.1 s", ``_loading``): Dask for sweep only, the LCM hardware
stack for hardware only, Meshcat's recorder only with --html, the report with the command. This module
itself imports the standard library and the light ``cli_parser``, ``commands`` and ``tasks.task_options``
(the tasks' options for a command's --help), so that every --help is answered in a fraction of a second;
it is the one module whose functions import the package's modules (tests/test_architecture.py).
"""

import contextlib
import gc
import json
import math
import os
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

from drake_hybrid.cli_parser import HARDWARE_DEFAULTS, HARDWARE_TASKS, build_parser
# DESCRIPTION (the top-level help) and each command's line live in the light drake_hybrid.commands,
# which the entry point answers --help from; cli.DESCRIPTION stays the name tests and readers use.
from drake_hybrid.commands import COMMAND_HELP, DESCRIPTION  # noqa: F401
from drake_hybrid.core.arguments import relative_tolerance
from drake_hybrid.core.errors import ConfigError, DrakeHybridError
from drake_hybrid.core.progress import Stages
from drake_hybrid.tasks.task_options import is_task_file

BAD_INPUT = 2                 # the exit code of bad input: a config field, a flag, a file
INTERRUPTED = 130             # Ctrl-C
INTERNAL_ERROR = 70           # a bug of drake_hybrid's (sysexits.h's EX_SOFTWARE)
# Errors that are a defect of the package whatever the input: the package refuses bad input with its own
# typed errors (DrakeHybridError), so one of these is never the user's mistake.
BUGS = (TypeError, LookupError, AttributeError, NameError, AssertionError)


class UsageError(DrakeHybridError):
    """Bad command-line input (printed as one line, exit code 2)."""


@contextlib.contextmanager
def _loading(args, what):
    """The command's first stage line while it loads ``what`` (its modules): from the entry point
    (``main``'s ``loading_line``), not with --quiet. Then the objects the imports made (modules,
    functions, Drake's bindings, sympy's and numba's tables: most of the process's) are moved out of
    the cyclic garbage collector's sight (``gc.freeze``): they live as long as the process, and each
    full collection, the last one at exit included, would scan them all again (1-2 s of a run)."""
    enabled = getattr(args, "loading_line", False) and not getattr(args, "quiet", False)
    with Stages(enabled=enabled)(f"drake-hybrid {args.command}: loading {what}"):
        yield
    gc.freeze()


def _options(args):
    """--option KEY=VALUE pairs as a dict (UsageError for an entry without '=')."""
    options = {}
    for option in getattr(args, "option", None) or []:
        if "=" not in option:
            raise UsageError(f"--option takes KEY=VALUE, got '{option}'")
        key, value = option.split("=", 1)
        options[key] = value
    return options


def _check_output_paths(args):
    """Refuse, before anything runs, output paths that cannot be written (UsageError naming the flag)."""
    for flag in ("out",):
        value = getattr(args, flag, None)
        if not value:
            continue
        if Path(value).exists() and not Path(value).is_dir():
            raise UsageError(f"--{flag} '{value}' exists and is not a directory")
        ancestor = _existing_ancestor(Path(value))
        if not ancestor.is_dir():
            raise UsageError(f"--{flag} '{value}' cannot be created: '{ancestor}' is a file, not a directory")
        if problem := _unwritable(ancestor):
            where = "is not writable" if ancestor == Path(value).absolute() else f"cannot be created in '{ancestor}'"
            raise UsageError(f"--{flag} '{value}' {where} (the system says: {problem}); give a directory you "
                             "can write to")
    for flag in ("html", "json", "plot"):
        value = getattr(args, flag, None)
        if not value or isinstance(value, bool):
            continue
        path = Path(value)
        if path.is_dir():
            raise UsageError(f"--{flag} '{value}' is a directory; give a file name")
        if not path.parent.is_dir():
            raise UsageError(f"--{flag} '{value}': the folder '{path.parent}' does not exist")
        problem = _unwritable(path.parent)
        if problem or (path.exists() and not os.access(path, os.W_OK)):
            why = f": the folder '{path.parent}' takes no new files (the system says: {problem})" if problem else ""
            raise UsageError(f"--{flag} '{value}' is not writable{why}")


def _unwritable(folder):
    """Why no file can be created in ``folder`` (the system's words, e.g. in /proc or a read-only disk), or ''."""
    try:
        tempfile.TemporaryFile(dir=folder).close()
    except OSError as error:
        return error.strerror or type(error).__name__
    return ""


def _existing_ancestor(path):
    path = path.absolute()
    while not path.exists():
        path = path.parent
    return path


def _config(args):
    from drake_hybrid.tasks.config import load_config
    from drake_hybrid.tasks.registry import get_task
    from drake_hybrid.tasks.task_file import load_task_file

    _check_output_paths(args)
    options = _options(args)
    if is_task_file(args.task):
        if options:
            raise UsageError("--option: a task file has no task options; edit its parameters instead")
        task, config = load_task_file(args.task)
    else:
        task = get_task(args.task)
        config = task.default_config(options) if options else task.default_config()
    if getattr(args, "config", None):
        try:
            config = load_config(path=args.config, defaults=config)
        except ConfigError as error:
            raise UsageError(f"--config: {error}") from None
        if config.task != task.name:
            raise UsageError(f"--config is for task '{config.task}', not '{task.name}'")
    if getattr(args, "mode", None):
        config.mode = args.mode
    if getattr(args, "duration", None) is not None:
        if not 0 < args.duration < math.inf:
            raise UsageError(f"--duration must be positive and finite (s), got {args.duration}")
        config.duration = args.duration
    return config


def command_simulate(args):
    with _loading(args, "Drake, numba and matplotlib"):
        from drake_hybrid.experiments.simulation import RunStopped, simulate
        from drake_hybrid.report.run import run_lines
        from drake_hybrid.tasks.registry import get_task
        from drake_hybrid.viz.outputs import write_run
    config = _config(args)
    out = Path(args.out) if args.out else Path("runs") / config.task
    meshcat = None
    if args.html:
        from drake_hybrid.viz.animation import quiet_meshcat, set_task_camera

        meshcat = quiet_meshcat()
        set_task_camera(meshcat, get_task(config.task))
    stages = Stages(enabled=not args.quiet)
    try:
        result, stopped = simulate(config, progress=not (args.no_progress or args.quiet), meshcat=meshcat,
                                   record_html=bool(args.html), stages=stages), None
    except RunStopped as error:
        result, stopped = error.result, error
    with stages(f"{config.task}: writing {out}" + ("" if args.no_plots else " (log, summary, plots)")):
        files = write_run(result, out, plots=not args.no_plots, html_path=args.html)
    if stopped is not None:
        print(f"{result.summary.task}: {stopped}", file=sys.stderr)
        print(f"  wrote what was logged up to the stop: {', '.join(str(f) for f in files)}", file=sys.stderr)
        return 1
    for line in run_lines(result):
        print(line)
    print(f"  wrote {', '.join(str(f) for f in files)}")
    return 0


def command_analyze(args):
    relative_tolerance(args.tolerance, "--tolerance", "the command line", error=UsageError)
    with _loading(args, "Drake"):
        from drake_hybrid.analysis.derivatives import DerivativeMismatchWarning
        from drake_hybrid.analysis.discrete_linearization import linearize_discrete
        from drake_hybrid.analysis.linearization import linearize_continuous
        from drake_hybrid.report.eigenvalues import judge_eigenvalues
        from drake_hybrid.tasks.registry import get_task
    config = _config(args)
    task = get_task(config.task)
    stages = Stages(enabled=not args.quiet)
    continuous = getattr(task, "continuous_plant", True)
    with warnings.catch_warnings():
        # The Jacobian check's own line (the report's) says what the warning would (which columns were replaced).
        warnings.simplefilter("ignore", DerivativeMismatchWarning)
        if continuous:
            result = linearize_continuous(config, tolerance=args.tolerance, stages=stages)
        else:
            result = linearize_discrete(config, tolerance=args.tolerance, settle_time=0.5, stages=stages)
    space = task.constraint_space(config)
    report = judge_eigenvalues(result, config, continuous, space.velocity_size, space.force_size,
                               tolerance=args.tolerance, strict=args.strict)
    for line in report.lines():
        print(line)
    if args.plot:
        import matplotlib.pyplot as plt

        from drake_hybrid.viz.eigenvalue_plots import eigenvalue_figure

        figure = eigenvalue_figure(result.match, title=f"{config.task}, {report.mode.value}", period=report.period,
                                   shifts=result.shifts)
        figure.savefig(args.plot, dpi=110)
        plt.close(figure)
        print(f"  wrote {args.plot}")
    if args.json:
        Path(args.json).write_text(json.dumps(report.as_dict(), indent=2))
        print(f"  wrote {args.json}")
    return report.exit_code


def command_sweep(args):
    with _loading(args, "Drake, numba and Dask"):
        from drake_hybrid.experiments.sweep import run_sweep
        from drake_hybrid.experiments.sweep_results import read_results
        from drake_hybrid.experiments.sweep_spec import SweepSpecError, load_spec
        from drake_hybrid.report.run import sweep_lines
        from drake_hybrid.tasks.task_file import load_task_file
    _check_output_paths(args)
    if args.workers < 0:
        raise UsageError(f"--workers must be 0 (serial, in this process) or a number of local Dask worker "
                         f"processes, got {args.workers}")
    task_name = load_task_file(args.task)[0].name if is_task_file(args.task) else args.task
    out = Path(args.out) if args.out else Path("runs") / f"sweep-{task_name}"
    try:
        spec = load_spec(path=args.grid)
    except SweepSpecError as error:
        raise SweepSpecError(f"--grid: {error}") from None
    try:
        run = run_sweep(task_name, spec, out, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                        retry_failed=args.retry_failed, progress=not args.no_progress)
    except SweepSpecError as error:                     # a value of the spec the config does not take
        raise SweepSpecError(f"--grid: sweep spec '{args.grid}': {error}") from None
    rows = read_results(run.results_path)
    for line in sweep_lines(task_name, run, rows):
        print(line)
    if args.plot:
        from drake_hybrid.viz.sweep_plots import save_sweep_plots

        for path in save_sweep_plots(rows, spec, out):
            print(f"  wrote {path}")
    return 0


def command_tasks(args):
    with _loading(args, "Drake"):
        from drake_hybrid.station.parsing import models_directory
        from drake_hybrid.tasks.hooks import ENTRY_POINT_GROUP, get_hook, hook_names
        from drake_hybrid.tasks.registry import TASKS
        from drake_hybrid.tasks.task_file_schema import read_task_file
    print("tasks (drake-hybrid simulate|analyze NAME):")
    for name, task in TASKS.items():
        print(f"  {name:24s} {task.description}")
    folder = models_directory() / "tasks"
    files = sorted(folder.glob("*.yaml"))
    if files:
        print(f"task files: a whole task in one YAML file (docs/task_files.md); run one with drake-hybrid "
              f"simulate|analyze {folder}/NAME.yaml, or copy it to start your own:")
    for path in files:
        print(f"  {path.name:24s} {read_task_file(path).description}")
    print(f"hooks a task file may name (hooks: [...]; more come from installed packages' {ENTRY_POINT_GROUP} "
          "entry points):")
    for name in hook_names():
        print(f"  {name:24s} {get_hook(name).description}")
    return 0


def command_hardware(args):
    """hil: lock-step loop vs the directly wired one; timing: a real-time run on memq:// (replayed
    robot); run: the controller side against a real driver at --lcm-url. Prints a summary; a
    watchdog stop is a fault (exit 1); --json FILE writes the figures."""
    with _loading(args, "Drake and numba"):
        from pydrake.lcm import DrakeLcm

        from drake_hybrid.hardware import panda
        from drake_hybrid.hardware.controller_side import build_controller_station
        from drake_hybrid.hardware.loop import compare_with_direct
        from drake_hybrid.hardware.messages import HardwareConfig
        from drake_hybrid.hardware.process_settings import NO_SETTINGS, RealTimeSettings
        from drake_hybrid.hardware.realtime import replay_timing, run_controller
        from drake_hybrid.report.hardware import hardware_fault_text, hardware_lines
    wait = getattr(args, "wait", None)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration must be a positive number of seconds (> 0), got {args.duration}")
    if wait is not None and not (math.isfinite(wait) and wait >= 0):
        raise UsageError(f"--wait must be a number of seconds >= 0, got {wait}")
    if args.speed is not None and not math.isfinite(args.speed):
        raise UsageError(f"--speed must be a finite number (m/s), got {args.speed}")
    _check_output_paths(args)
    start = time.perf_counter()
    task = getattr(panda, HARDWARE_TASKS[args.task])()
    duration, speed = HARDWARE_DEFAULTS[args.mode]
    config = panda.panda_config(task, duration=args.duration or duration,
                                wrist_sensor=args.wrench_source == "force_torque",
                                speed=speed if args.speed is None else args.speed)
    hardware = HardwareConfig(wrench_source=args.wrench_source).validate()
    settings = NO_SETTINGS if getattr(args, "no_realtime", False) else RealTimeSettings()
    if args.mode == "hil":
        figures = compare_with_direct(config, hardware)[0]
    elif args.mode == "timing":
        if not args.lcm_url.startswith("memq://"):
            raise UsageError(f"--lcm-url: the timing run replays the robot in this process over memq://, got "
                             f"{args.lcm_url!r}; use 'run' with a real driver")
        timing, _ = replay_timing(config, hardware, seconds=config.duration, lcm_url=args.lcm_url, settings=settings)
        figures = timing.summary
    else:
        lcm = DrakeLcm(args.lcm_url)
        station = build_controller_station(config, lcm, hardware, initial_positions=task.joint_guess,
                                           with_loggers=False)
        print(f"waiting up to {wait:g} s for {hardware.status_channel} on {args.lcm_url} ...", file=sys.stderr)
        timing = run_controller(station, lcm, config.duration, first_wait=wait, wall_clock_stamps=True,
                                settings=settings)
        if timing.summary["commands_published"] == 0:
            print(f"drake-hybrid hardware: no valid status on {hardware.status_channel}; nothing was commanded",
                  file=sys.stderr)
            return 1
        figures = timing.summary
    figures["wall_time_s"] = time.perf_counter() - start
    for line in hardware_lines(figures, args.task, args.mode, args.wrench_source, getattr(args, "lcm_url", None)):
        print(line)
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2, default=str) + "\n")
        print(f"  wrote {args.json}")
    if fault := hardware_fault_text(figures, args.task, args.mode):
        print(fault, file=sys.stderr)
        return 1
    return 0


def make_parser():
    """The ``drake-hybrid`` parser (``cli_parser.build_parser``) with this module's commands."""
    return build_parser({"simulate": command_simulate, "analyze": command_analyze, "sweep": command_sweep,
                         "hardware": command_hardware, "tasks": command_tasks})



def main(argv=None, loading_line=False):
    """Run the command of ``argv``; ``loading_line``: print its first stage line while it loads what it
    uses (the ``drake-hybrid`` entry point does; a script or a test calling ``main`` gets its output only).

    Returns the command's exit code: 0; 1 for a run that stopped early, a linearization not matched, a
    watchdog fault or an error not classified below; ``BAD_INPUT`` (2) for the package's own errors
    (``DrakeHybridError``, which name the field, flag or file) and a missing file, in one line;
    ``INTERRUPTED`` (130) for Ctrl-C; ``INTERNAL_ERROR`` (70) for an error that is a bug of the package's
    (``BUGS``), printed with its traceback. ``--traceback`` (or DRAKE_HYBRID_TRACEBACK=1) lets every
    error through."""
    args = make_parser().parse_args(argv)
    args.loading_line = loading_line
    if args.traceback or os.environ.get("DRAKE_HYBRID_TRACEBACK", "") not in ("", "0"):
        return args.func(args)
    try:
        return args.func(args)
    except SystemExit:
        raise
    except KeyboardInterrupt:
        print(f"drake-hybrid {args.command}: interrupted", file=sys.stderr)
        return INTERRUPTED
    except (DrakeHybridError, FileNotFoundError) as error:     # bad input: config, flags, files
        print(f"drake-hybrid {args.command}: {_one_line(error)}", file=sys.stderr)
        return BAD_INPUT
    except BUGS as error:
        traceback.print_exc()
        print(f"drake-hybrid {args.command}: internal error, a bug in drake_hybrid and not a mistake in your "
              f"input: {type(error).__name__}: {_one_line(error)} (please report it with the traceback above)",
              file=sys.stderr)
        return INTERNAL_ERROR
    except Exception as error:   # noqa: BLE001 -- anything else: one line, with the way to see more
        print(f"drake-hybrid {args.command}: {type(error).__name__}: {_one_line(error)} "
              "(run with --traceback for details)", file=sys.stderr)
        return 1


def _one_line(error):
    """The first line of an error's message (its type's name if it has none)."""
    text = str(error).strip()
    if isinstance(error, KeyError) and len(error.args) == 1:
        text = str(error.args[0])
    return text.splitlines()[0] if text else type(error).__name__


if __name__ == "__main__":
    sys.exit(main())
