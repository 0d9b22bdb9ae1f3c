"""The ``drake-hybrid`` command line: one function per command and the parser (the entry point,
``drake_hybrid.__main__``, imports this module after its first line). ``DESCRIPTION`` (from
``drake_hybrid.commands``) is the top-level ``--help`` text, for users; this docstring is for readers
of the source and is not printed (tests/test_cli_help.py checks both, and the help against the README's
synopsis).

Each command loads what it uses when it runs, under its first stage line ("drake-hybrid simulate:
loading Drake, numba and matplotlib ... 2.1 s", ``_loading``): Dask for sweep only, the LCM hardware
stack for hardware only, Meshcat's recorder only with --html. This module itself imports the standard
library, numpy and the light ``commands``, ``control.gains`` and ``tasks.task_options`` (the tasks'
options for a command's --help), so that every --help is answered in a fraction of a second; it is the
one module whose functions import the package's modules (tests/test_architecture.py).

Size: one command per function (simulate, analyze, sweep, tasks, hardware) and the parser whose
help the README's synopsis mirrors (tests/test_cli_help.py).
"""

import argparse
import contextlib
import gc
import json
import math
import os
import re
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

# DESCRIPTION (the top-level help) and each command's line live in the light drake_hybrid.commands,
# which the entry point answers --help from; cli.DESCRIPTION stays the name tests and readers use.
from drake_hybrid.commands import COMMAND_HELP, DESCRIPTION, top_level_parser  # noqa: F401
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.arguments import relative_tolerance
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.progress import Stages
from drake_hybrid.tasks.task_options import BUILT_IN_OPTIONS, built_in_option_help, is_task_file


class UsageError(ValueError):
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


def _task_argument(value):
    """The TASK argument: a task's name, or a task file (FILE.yaml, tasks/task_file.py)."""
    if is_task_file(value) or value in BUILT_IN_OPTIONS:
        return value
    raise argparse.ArgumentTypeError(f"invalid choice: '{value}' (choose from {', '.join(sorted(BUILT_IN_OPTIONS))}, "
                                     "or give a task file FILE.yaml)")


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


def _fmt(values):
    return ", ".join(f"{v.real:.4g}{v.imag:+.4g}j" if abs(v.imag) > 1e-9 else f"{v.real:.4g}" for v in values)


def _eigenvalues_by_row(controller, summary):
    """" by row, velocity: 'x-dot' -10, 'theta-dot' -8; force: 'F' -10": each designed eigenvalue with its
    row, or by loop when a gain couples the rows."""
    from drake_hybrid.analysis.design import designed_eigenvalues_by_row  # (loaded with the command)
    by_row = designed_eigenvalues_by_row(controller.validated_gains(), controller.mode, controller.kinematic_rows,
                                         controller.num_joints - controller.task_size)
    if by_row is None:
        designed = np.array([complex(*e) for e in summary["predicted_eigenvalues"]])
        return f" (by loop: a gain couples the rows): {_fmt(designed)}"
    velocity, force, null_space = by_row
    text = (" by row, velocity: " + ", ".join(f"'{row['name']}' {_fmt(values)}"
                                               for row, values in zip(summary["velocity_rows"], velocity))
            + "; force: " + ", ".join(f"'{row['name']}' {_fmt(values)}" + (" (held: -w_c, -2 w_c)" if row.get("held")
                                                                              else "")
                                      for row, values in zip(summary["force_rows"], force)))
    if null_space:
        text += f"; self-motion: {_fmt(np.array(null_space))} (-K_n per extra joint)"
    return text


def _event_text(time, events):
    """Where ``time`` (s) falls among the run's phases (summary["events"]): inside a span, or within 0.3 s
    after its edge or an instant; empty if nowhere near one (or only near phases that cause no error)."""
    for event in events or ():
        if not event.get("explains_errors", True):
            continue
        start, end = event["start"], event.get("end")
        if end is not None and start <= time <= end:
            return f", {time - start:.2f} s after the start of: {event['label']}"
        for edge, word in ((start, "the start"), (end, "the end")):
            if edge is not None and 0 <= time - edge <= 0.3:
                return f", {time - edge:.2f} s after {word if end is not None else 'the moment'} of: {event['label']}"
    return ""


def _notes_on(name, notes):
    """The numbers (from 1) of the run's ``notes`` that name the row ``name`` (up to a comma or a parenthesis:
    "F" of "F, along E_f = [0 1 0]") as a word, e.g. "x-dot's error ...": the notes about that row."""
    short = re.split(r",| \(", name)[0].strip()
    pattern = re.compile(rf"(?<![\w/-]){re.escape(short)}(?![\w/-])")
    return [n + 1 for n, note in enumerate(notes or ()) if pattern.search(note)]


SCALE_WORDS = {"rows in its units": "the largest command in its units",
               "run": "the run's command scale (speed or force)"}


def _row_text(row, events=(), notes=()):
    """One row's errors: absolute in its units, % of its scale (its command; for a row commanded to zero,
    the run's speed or force: ``metrics.row_scales``), settling from contact;
    when its settled max falls in or just after a phase of the run, that phase; the numbers of the run's
    ``notes`` that name the row (the ones that say why), if any."""
    units = row["units"]
    about = _notes_on(row["name"], notes)
    pointer = "" if not about else f"; see note{'s' if len(about) > 1 else ''} {', '.join(map(str, about))}"

    def amount(value, percent):
        if value is None:
            return "-"
        return f"{value:.3g} {units}" + (f" ({percent:.2f} %)" if percent is not None else "")

    if row.get("held"):
        measured = row.get("max_measured_force_after_contact")
        return "held by the controller (no force commanded)" + (
            "" if measured is None else f"; measured force up to {measured:.3g} {units} after contact")
    command = f"command {row['command']:.3g} {units}" if row["command"] > 0 else "command 0"
    final = None if row["final_error"] is None else abs(row["final_error"])
    settled = amount(row["max_error_after_5_time_constants"], row["max_error_percent_after_5_time_constants"])
    when = row.get("max_error_time_after_5_time_constants")
    if when is not None and row["max_error_after_5_time_constants"]:
        phase = _event_text(when, events)
        settled += f" at t = {when:.3f} s" + phase
    text = f"{command}; final error {amount(final, row['final_error_percent'])}, settled max {settled}"
    settle = row["settling_time_1_percent"]
    if settle is not None:
        text += (f", within 1 % from {settle:.3f} s after contact on" if np.isfinite(settle)
                 else ", not within 1 % at the end")
    if row.get("scale_of") in SCALE_WORDS:
        text += f" (% of {row['scale']:.3g}, {SCALE_WORDS[row['scale_of']]})"
    return text + pointer


IMPEDANCE_REALIZED = 2.0      # % of the command: a run this close to its driven impedance realizes it


def _impedance_text(check):
    """summary["impedance"] in one line: the run against the designed impedance driven by its measured F_v."""
    forces = ", ".join(f"{force:.3g}" for force in check["max_tangential_force"])
    percent = check["max_difference_percent"]
    agreement = (f"within {percent:.2g} % of the command" if percent is not None else
                 "within " + ", ".join(f"{d:.3g}" for d in check["max_difference"]) + " (rows' units)")
    verdict = ("the rows' errors above are the designed impedance's answer to its start and to F_v"
               if percent is not None and percent <= IMPEDANCE_REALIZED else
               "the run does not realize the designed impedance that closely (contact transients, saturation, a "
               "model error?)")
    return (f"impedance (3.2-11) driven by the measured F_v (settled max |F_v| per row: {forces}): the velocity "
            f"errors it predicts are {agreement} of the measured ones (settled): {verdict}")


def _residual_text(summary):
    """max |C(r)| after contact in C's units: one figure if every row has the same unit, else one per row."""
    from drake_hybrid.experiments.metrics import display_unit

    residual = summary["max_constraint_residual_after_contact"]
    if residual is None:
        return "no contact made"
    units, rows = summary.get("constraint_units"), summary.get("max_constraint_residual_rows_after_contact")
    if not units or not rows:
        return f"max |C(r)| after contact {residual:.3g} (in the units of C's rows)"
    if len(set(units)) == 1:
        return f"max |C(r)| after contact {residual:.3g} {display_unit(units[0])}"
    figures = ", ".join(f"{value:.3g} {display_unit(unit)}" for value, unit in zip(rows, units))
    return f"max |C_i(r)| after contact, per row of C: {figures}"


def command_simulate(args):
    with _loading(args, "Drake, numba and matplotlib"):
        from drake_hybrid.experiments.path_report import path_text
        from drake_hybrid.experiments.simulation import RunStopped, simulate
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
    s = result.summary
    if stopped is not None:
        print(f"{s['task']}: {stopped}", file=sys.stderr)
        print(f"  wrote what was logged up to the stop: {', '.join(str(f) for f in files)}", file=sys.stderr)
        return 1
    print(f"{s['task']} ({s['mode']}), {s['duration']:.2f} s simulated in {s['wall_time']:.1f} s "
          f"(real-time factor {s['real_time_factor']:.2f})")
    print(f"  designed eigenvalues{_eigenvalues_by_row(result.scenario.controller, s)}"
          f" (slowest time constant {s['design_time_constant']:.3f} s)")
    start = s["contact_time"]
    since = "from t = 0" if start == 0 else f"from contact at t = {start:.3f} s"
    print(f"  errors per row, in its own units and in % of its command ({since}; 'settled': after contact + 5 "
          f"design time constants, t >= {start + 5 * s['design_time_constant']:.3f} s):")
    for what, rows in (("velocity", s["velocity_rows"]), ("force", s["force_rows"])):
        for row in rows:
            print(f"    {what} {row['name']}: {_row_text(row, s.get('events'), s.get('notes'))}")
    if s.get("invalid_wrench_samples"):
        print(f"  {s['invalid_wrench_samples']} logged sample(s) with an invalid measured wrench (a sensor dropout): "
              "the force figures leave them out (their F, e_f and F_v read NaN in log.npz)")
    if s.get("impedance"):
        print(f"  {_impedance_text(s['impedance'])}")
    print(f"  {_residual_text(s)}")
    for line in path_text(s["path"]) if s.get("path") else ():
        print(f"  {line}")
    for n, note in enumerate(s.get("notes", []), start=1):
        print(f"  note {n}: {note}")
    print(f"  wrote {', '.join(str(f) for f in files)}")
    return 0


def _sampled_loop_text(config, period):
    """What ``linearize_discrete`` linearized (``period``: its step, the plant's) against what ``simulate`` runs."""
    low_pass = getattr(config.sensor, "bandwidth_hz", 0.0)
    simulated = (f"simulate runs the controller every {config.control_period * 1e3:g} ms (control_period)"
                 + (f" with a {low_pass:g} Hz wrench low-pass" if low_pass > 0 else ", no low-pass either"))
    return (f"the sampled loop linearized at the plant's step h = {period * 1e3:g} ms, with the controller at that "
            f"rate (every update at the same instants: one map per step) and no wrench low-pass; {simulated}")


def command_analyze(args):
    relative_tolerance(args.tolerance, "--tolerance", "the command line", error=UsageError)
    with _loading(args, "Drake"):
        from drake_hybrid.analysis.derivatives import DerivativeMismatchWarning
        from drake_hybrid.analysis.discrete_linearization import linearize_discrete
        from drake_hybrid.analysis.linearization import linearize_continuous
        from drake_hybrid.analysis.matching import nyquist_split, predicted_match, shift_indices
        from drake_hybrid.tasks.registry import get_task
    config = _config(args)
    task = get_task(config.task)
    stages = Stages(enabled=not args.quiet)
    with warnings.catch_warnings():
        # The Jacobian check's own line below says what the warning would (which columns were replaced).
        warnings.simplefilter("ignore", DerivativeMismatchWarning)
        if getattr(task, "continuous_plant", True):
            result = linearize_continuous(config, tolerance=args.tolerance, stages=stages)
            how = "Linearize of the continuous closed loop"
        else:
            result = linearize_discrete(config, tolerance=args.tolerance, settle_time=0.5, stages=stages)
            how = (f"Jacobian of the discrete closed loop's one-period map (h = {result.period * 1e3:g} ms), "
                   "eigenvalues log(mu)/h,")
    match = result.match
    controller_mode = ControlMode.parse(config.mode)
    space = task.constraint_space(config)
    k, m = space.velocity_size, space.force_size
    print(f"{config.task} ({controller_mode.value}): {how} at a contact equilibrium "
          f"(residual {result.equilibrium_residual:.2g}; the linearization itself took {result.wall_time:.2f} s)")
    if period := getattr(result, "period", None):
        print(f"  {_sampled_loop_text(config, period)}")
    # With the task's predicted shifts (physics the paper's model leaves out), pair against those.
    shown = result.shifted_match or match
    shifted = shift_indices(match.predicted, result.shifts)
    errors = np.abs(shown.partner - match.predicted) / np.abs(match.predicted)
    print(f"  {'designed':>22}  {'linearized':>22}  rel. error")
    for i, (p, q, error) in enumerate(zip(match.predicted, shown.partner, errors)):
        line = f"  {_fmt([p]):>22}  {_fmt([q]):>22}  {100 * error:8.3f} %"
        if i in shifted and error > args.tolerance:
            line += (f"  missed; predicted {_fmt([shifted[i].predicted])} "
                     f"({100 * shown.relative_error[i]:.2f} % from it): see [{sorted(shifted).index(i) + 1}]")
        print(line)
    for n, i in enumerate(sorted(shifted)):
        # one reason per run of shifts that share it (an impedance's rows meeting one contact)
        following = sorted(shifted)[n + 1] if n + 1 < len(shifted) else None
        last = following is None or shifted[following].reason != shifted[i].reason
        print(f"  [{n + 1}] {_fmt([shifted[i].designed])} -> {_fmt([shifted[i].predicted])}"
              + (f": {shifted[i].reason}" if last else ";"))
    print(f"  marginal (theory: {len(match.marginal_partners)} x 0, unregulated positions): "
          f"{_fmt(match.marginal_partners)}")
    other, nyquist = nyquist_split(match.extra, period)
    print(f"  other modes (contact, filter, sampling, joint space): {_fmt(np.sort_complex(other))}")
    if nyquist.size:
        print(f"  at the step's Nyquist frequency pi/h = {np.pi / period:.4g} 1/s (multipliers mu < 0, which log(mu)/h "
              f"maps to ln|mu|/h +- j pi/h: real modes that change sign every step, none of them designed): "
              f"{_fmt(np.sort_complex(nyquist))}")
    if result.shifted_match is not None:
        raw, paired = 100 * np.max(match.relative_error), 100 * np.max(errors)
        if abs(raw - paired) >= 0.005:
            print(f"  worst deviation from the design: {paired:.2f} % with each designed eigenvalue paired as the "
                  f"task's prediction pairs it (the table above); {raw:.2f} % paired by nearest distance alone "
                  "(--json's relative_error; the figure docs/baselines.md quotes)")
    tolerance = f"{100 * args.tolerance:g} %"
    predicted_by = predicted_match(result, args.tolerance)
    if match.matched:
        verdict, code = f"every designed eigenvalue within {tolerance}, no other mode unstable: matched", 0
    elif predicted_by is not None:
        parts = []
        if predicted_by is result.shifted_match and np.any(errors > args.tolerance):
            parts.append(f"{int(np.sum(errors > args.tolerance))} designed eigenvalue(s) missed by more than "
                         f"{tolerance}, each within {tolerance} of the task's prediction for it")
        if predicted_by.unstable_extra.size:
            parts.append(f"{predicted_by.unstable_extra.size} unstable mode(s), each within {tolerance} of its "
                         "predicted value (below)")
        verdict = ", ".join(parts) + ", no other mode unstable: matched as predicted"
        code = 1 if args.strict else 0
        if args.strict:
            verdict += " (--strict: counted as a miss)"
    else:
        unexplained = "unstable modes" if match.unstable_extra.size else f"misses beyond {tolerance} not predicted"
        verdict, code = f"not matched: {unexplained}", 1
    print(f"  {verdict}")
    for diagnosis in getattr(result, "unstable_modes", []):
        print(f"  {diagnosis.summary()}")
    check = getattr(result, "jacobian_check", None)
    print(f"  {check.summary()}" if check is not None else
          "  Jacobian: the one-period map's, by central differences (a sampled loop has no AutoDiffXd Jacobian "
          "to check it against); eigenvalues from it")
    step_check = getattr(result, "step_check", None)
    if step_check is not None:
        print(f"  {step_check.summary()}")
    if args.plot:
        import matplotlib.pyplot as plt

        from drake_hybrid.viz.eigenvalue_plots import eigenvalue_figure

        figure = eigenvalue_figure(match, title=f"{config.task}, {controller_mode.value}", period=period,
                                   shifts=result.shifts)
        figure.savefig(args.plot, dpi=110)
        plt.close(figure)
        print(f"  wrote {args.plot}")
    if args.json:
        payload = match.as_dict()
        payload["predicted_shifts"] = [{"designed": [float(np.real(x.designed)), float(np.imag(x.designed))],
                                        "predicted": [float(np.real(x.predicted)), float(np.imag(x.predicted))],
                                        "reason": x.reason} for x in result.shifts]
        if result.shifted_match is not None:
            payload["paired_by_prediction"] = {"partners": [[float(np.real(q)), float(np.imag(q))] for q in shown.partner],
                                               "relative_error": [float(e) for e in errors]}
        if period:
            payload["nyquist_frequency"] = float(np.pi / period)
        payload["matched_as_predicted"] = bool(match.matched or predicted_by is not None)
        payload.update({"gains": config.gains.as_lists(k, m, controller_mode), "mode": controller_mode.value,
                        "method": "continuous" if getattr(task, "continuous_plant", True) else "discrete",
                        "velocity_dim": k, "force_dim": m, "task": config.task,
                        "equilibrium_residual": result.equilibrium_residual, "wall_time": result.wall_time,
                        "jacobian_check": check.as_dict() if check is not None else {"used": "central differences"},
                        "unstable_modes": [d.as_dict() for d in getattr(result, "unstable_modes", [])],
                        "step_check": step_check.as_dict() if step_check is not None else None})
        Path(args.json).write_text(json.dumps(payload, indent=2))
        print(f"  wrote {args.json}")
    return code


def _where(workers):
    """Where a sweep ran, in the command line's terms (``SweepRun.workers``: "serial", "local:N" or an address)."""
    if workers == "serial":
        return "serially in this process (--workers 0)"
    if workers.startswith("local:"):
        return f"on {workers.split(':', 1)[1]} local Dask worker processes (--workers)"
    return f"on the Dask scheduler at {workers} (--scheduler)"


def command_sweep(args):
    with _loading(args, "Drake, numba and Dask"):
        from drake_hybrid.experiments.sweep import run_sweep
        from drake_hybrid.experiments.sweep_results import read_results
        from drake_hybrid.experiments.sweep_spec import SweepSpecError, load_spec
        from drake_hybrid.tasks.task_file import load_task_file
    _check_output_paths(args)
    if args.workers < 0:
        raise UsageError(f"--workers must be 0 (serial, in this process) or a number of local Dask worker "
                         f"processes, got {args.workers}")
    task_name = load_task_file(args.task)[0].name if is_task_file(args.task) else args.task
    out = Path(args.out) if args.out else Path("runs") / f"sweep-{task_name}"
    try:
        try:
            spec = load_spec(path=args.grid)
        except SweepSpecError as error:
            raise SweepSpecError(f"--grid: {error}") from None
        try:
            run = run_sweep(task_name, spec, out, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                            retry_failed=args.retry_failed, progress=not args.no_progress)
        except SweepSpecError as error:                 # a value of the spec the config does not take
            raise SweepSpecError(f"--grid: sweep spec '{args.grid}': {error}") from None
    except (SweepSpecError, ValueError) as error:
        print(f"drake-hybrid sweep: {_one_line(error)}", file=sys.stderr)
        return 2
    rows = read_results(run.results_path)
    stable = sum(1 for row in rows if row.get("stable"))
    if run.evaluated:
        done = f"{run.evaluated} of {run.points} points evaluated in {run.wall_time:.1f} s {_where(run.workers)}"
    else:
        done = f"nothing to run: all {run.points} points already in the table"
    print(f"{task_name}: {done}; {len(rows)} in the table, {stable} stable, {run.failures} with errors")
    print(f"  wrote {run.results_path}")
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


def _task_options_epilog():
    """The valid --option keys of every built-in task (from its typed Options, ``tasks.task_options``)."""
    lines = ["task options (--option KEY=VALUE, repeatable):"]
    for name in BUILT_IN_OPTIONS:
        entries = built_in_option_help(name)
        lines.append(f"  {name}:" + (" none" if not entries else ""))
        lines += [f"    {entry}" for entry in entries]
    return "\n".join(lines)


HARDWARE_TASKS = {"panda-drum": "panda_drum_task", "panda-table": "panda_table_task"}   # hardware.panda's
HARDWARE_DEFAULTS = {"hil": (2.0, 0.05), "timing": (10.0, 0.02), "run": (10.0, 0.02)}   # --duration s, --speed m/s


def _milliseconds(stats):
    if stats is None:
        return "none measured"
    return f"p50 {stats['p50'] * 1e3:.3g} ms, p99 {stats['p99'] * 1e3:.3g} ms, max {stats['max'] * 1e3:.3g} ms"


def _hardware_summary(args, figures):
    """The lines ``drake-hybrid hardware MODE`` prints: what ran, how long, ticks, misses and the stop."""
    head = f"{args.task}, {args.mode} (wrench from {args.wrench_source})"
    if args.mode == "hil":
        lines = [f"{head}: {figures['duration']:.2f} s in lock step over memq:// and directly wired, "
                 f"in {figures['wall_time_s']:.1f} s"]
        settled = 5 * figures["design_time_constant"]
        for what in ("velocity", "force"):
            direct, loop = figures[f"{what}_error_direct_percent"], figures[f"{what}_error_hardware_loop_percent"]
            if direct is None or loop is None:
                lines.append(f"  {what} error after 5 design time constants: not measured, the run is shorter "
                             f"than {settled:.3g} s (--duration)")
            else:
                lines.append(f"  {what} error after 5 design time constants: directly wired {direct:.4g} %, "
                             f"hardware loop {loop:.4g} % (they differ by "
                             f"{figures[f'{what}_error_difference_points']:.2g} percentage points)")
        lines.append(f"  largest difference over the run: joints {figures['max_joint_difference_rad']:.2g} rad, "
                     f"force {figures['max_force_difference_N']:.2g} N")
        delay = figures["status_delay_simulated_s"]
        lines.append(f"  {figures['commands_published']} commands published; message delay (status sent to used, "
                     f"simulated time): {'none measured' if delay is None else _milliseconds(delay)}"
                     + ("" if delay is None else " (LCM timestamps are whole microseconds: 1 us is their "
                        "resolution, not a delay)"))
        return lines
    ticks, period = figures["ticks"], figures["period_s"]
    where = "replayed robot over " if args.mode == "timing" else "driver at "
    misses = figures["deadline_misses"]
    return [f"{head}: {ticks} ticks at {figures['rate_hz']:.0f} Hz over {figures['wall_s']:.2f} s of wall clock "
            f"({where}{args.lcm_url}), in {figures['wall_time_s']:.1f} s",
            f"  controller cost per tick (status in to command out): {_milliseconds(figures['controller_cost_s'])}",
            f"  period jitter |interval - {period * 1e3:g} ms|: {_milliseconds(figures['period_jitter_s'])}",
            f"  deadline misses (command more than {period * 1e3:g} ms after its status was sent): {misses} of "
            f"{ticks} ticks ({100 * misses / ticks:.1f} %)",
            f"  ticks without a new status: {figures['ticks_without_new_status']}; commands published: "
            f"{figures['commands_published']} of {ticks}"]


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
        from drake_hybrid.hardware.realtime import replay_timing, run_controller
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
    if args.mode == "hil":
        figures = compare_with_direct(config, hardware)[0]
    elif args.mode == "timing":
        if not args.lcm_url.startswith("memq://"):
            raise UsageError(f"--lcm-url: the timing run replays the robot in this process over memq://, got "
                             f"{args.lcm_url!r}; use 'run' with a real driver")
        timing, _ = replay_timing(config, hardware, seconds=config.duration, lcm_url=args.lcm_url)
        figures = timing.summary
    else:
        lcm = DrakeLcm(args.lcm_url)
        station = build_controller_station(config, lcm, hardware, initial_positions=task.joint_guess,
                                           with_loggers=False)
        print(f"waiting up to {wait:g} s for {hardware.status_channel} on {args.lcm_url} ...", file=sys.stderr)
        timing = run_controller(station, lcm, config.duration, first_wait=wait, wall_clock_stamps=True)
        if timing.summary["commands_published"] == 0:
            print(f"drake-hybrid hardware: no valid status on {hardware.status_channel}; nothing was commanded",
                  file=sys.stderr)
            return 1
        figures = timing.summary
    figures["wall_time_s"] = time.perf_counter() - start
    for line in _hardware_summary(args, figures):
        print(line)
    if figures["stop"] is None:
        print("  no fault: the watchdog did not stop the controller")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2, default=str) + "\n")
        print(f"  wrote {args.json}")
    if figures["stop"] is not None:
        print(f"{args.task}, {args.mode}: fault: the watchdog stopped the controller, {figures['stop']}",
              file=sys.stderr)
        return 1
    return 0


def make_parser():
    parser, sub = top_level_parser()
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--traceback", action="store_true",
                        help="show the full Python traceback of an error (also DRAKE_HYBRID_TRACEBACK=1)")
    modes = [m.value for m in ControlMode]
    epilog = _task_options_epilog()
    task_help = (", ".join(sorted(BUILT_IN_OPTIONS))
                 + ", or a task file FILE.yaml (a whole task in one file: models/tasks/)")
    simulate = sub.add_parser("simulate", parents=[common],
                              help=COMMAND_HELP["simulate"],
                              description="Simulate a task; writes log.npz, summary.json, config.yaml and the "
                                          "plots to --out.",
                              epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    simulate.add_argument("task", type=_task_argument, metavar="TASK", help=task_help)
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
    simulate.set_defaults(func=command_simulate)
    analyze = sub.add_parser("analyze", parents=[common],
                             help=COMMAND_HELP["analyze"],
                             description="Linearize the closed loop at a contact equilibrium and compare its "
                                         "eigenvalues with the ones the gains design.",
                             epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    analyze.add_argument("task", type=_task_argument, metavar="TASK", help=task_help)
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
    analyze.set_defaults(func=command_analyze)
    sweep = sub.add_parser("sweep", parents=[common],
                           help=COMMAND_HELP["sweep"],
                           description="Evaluate a grid or Monte Carlo sample of config fields: per point a short "
                                       "simulation, two linearizations and the verdicts, appended to "
                                       "DIR/results.csv (docs/stability.md).")
    sweep.add_argument("task", type=_task_argument, metavar="TASK", help=task_help)
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
    sweep.set_defaults(func=command_sweep)
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
             "controller side over memq:// in this process; print the controller's cost per tick, the period "
             "jitter and the deadline misses."),
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
        parser_.add_argument("--json", metavar="FILE", help="also write the figures to this JSON file")
        parser_.set_defaults(func=command_hardware)
    tasks = sub.add_parser("tasks", parents=[common], help=COMMAND_HELP["tasks"],
                           description="List the tasks and what each one does.")
    tasks.set_defaults(func=command_tasks)
    return parser


def main(argv=None, loading_line=False):
    """Run the command of ``argv``; ``loading_line``: print its first stage line while it loads what it
    uses (the ``drake-hybrid`` entry point does; a script or a test calling ``main`` gets its output only)."""
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
        return 130
    except (ValueError, TypeError, KeyError, FileNotFoundError) as error:   # bad input: config, flags, files
        print(f"drake-hybrid {args.command}: {_one_line(error)}", file=sys.stderr)
        return 2
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
