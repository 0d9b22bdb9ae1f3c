"""Command line: ``drake-hybrid simulate|analyze|tasks``.

    drake-hybrid simulate window-washing [--duration S] [--out DIR] [--mode MODE] [--config FILE] [--html FILE]
    drake-hybrid analyze window-washing [--mode MODE] [--json FILE] [--plot FILE.png] [--config FILE]
    drake-hybrid sweep window-washing --grid SPEC.yaml [--out DIR] [--scheduler ADDRESS] [--workers N] [--resume]
    drake-hybrid tasks
"""

import argparse
import json
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from pydrake.geometry import Meshcat

from drake_hybrid.analysis.linearization import linearize_continuous, linearize_discrete
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.experiments.sweep import read_results, run_sweep
from drake_hybrid.experiments.sweep_spec import SweepSpecError, load_spec
from drake_hybrid.scenario.config import load_config
from drake_hybrid.scenario.tasks import TASKS, get_task
from drake_hybrid.viz.animation import set_task_camera
from drake_hybrid.viz.outputs import write_run
from drake_hybrid.viz.plotting import eigenvalue_figure, save_sweep_plots


def _config(args):
    task = get_task(args.task)
    options = dict(option.split("=", 1) for option in (getattr(args, "option", None) or []))
    config = task.default_config(options) if options else task.default_config()
    if getattr(args, "config", None):
        config = load_config(path=args.config, defaults=config)
        if config.task != task.name:
            raise SystemExit(f"--config is for task '{config.task}', not '{task.name}'")
    if getattr(args, "mode", None):
        config.mode = args.mode
    if getattr(args, "duration", None) is not None:
        if not args.duration > 0:
            raise SystemExit(f"--duration must be positive, got {args.duration}")
        config.duration = args.duration
    return config


def _fmt(values):
    return ", ".join(f"{v.real:.4g}{v.imag:+.4g}j" if abs(v.imag) > 1e-9 else f"{v.real:.4g}" for v in values)


def command_simulate(args):
    config = _config(args)
    out = Path(args.out) if args.out else Path("runs") / config.task
    meshcat = None
    if args.html:


        meshcat = Meshcat()
        set_task_camera(meshcat, get_task(config.task))
    result = simulate(config, progress=not args.no_progress, meshcat=meshcat, record_html=bool(args.html))
    files = write_run(result, out, plots=not args.no_plots)
    if args.html:
        Path(args.html).write_text(result.html)
        files.append(Path(args.html))
    s = result.summary
    print(f"{s['task']} ({s['mode']}), {s['duration']:.2f} s simulated in {s['wall_time']:.1f} s "
          f"(real-time factor {s['real_time_factor']:.2f})")
    print(f"  designed eigenvalues: {_fmt(np.array([complex(*e) for e in s['predicted_eigenvalues']]))}"
          f" (slowest time constant {s['design_time_constant']:.3f} s)")
    print(f"  final velocity error {s['final_velocity_error_percent']:.3f} % of the commanded speed, "
          f"final force error {s['final_force_error_percent']:.3f} % of the commanded force")
    print(f"  within 1 % after {s['velocity_settling_time_1_percent']:.3f} s (velocity), "
          f"{s['force_settling_time_1_percent']:.3f} s (force); max |C(r)| {s['max_constraint_residual']:.3g}")
    print(f"  wrote {', '.join(str(f) for f in files)}")
    return 0


def command_analyze(args):
    config = _config(args)
    task = get_task(config.task)
    if getattr(task, "continuous_plant", True):
        result = linearize_continuous(config, tolerance=args.tolerance)
        how = "Linearize of the continuous closed loop"
    else:
        result = linearize_discrete(config, tolerance=args.tolerance, settle_time=0.5)
        how = (f"Jacobian of the discrete closed loop's one-period map (h = {result.period * 1e3:g} ms), "
               "eigenvalues log(mu)/h,")
    match = result.match
    controller_mode = ControlMode.parse(config.mode)
    space = task.constraint_space(config)
    k, m = space.velocity_size, space.force_size
    print(f"{config.task} ({controller_mode.value}): {how} at a contact equilibrium "
          f"(residual {result.equilibrium_residual:.2g}) in {result.wall_time:.2f} s")
    print(f"  {'predicted':>22}  {'linearized':>22}  rel. error")
    for p, q, e in zip(match.predicted, match.partner, match.relative_error):
        print(f"  {_fmt([p]):>22}  {_fmt([q]):>22}  {100 * e:8.3f} %")
    print(f"  marginal (theory: {len(match.marginal_partners)} x 0, unregulated positions): "
          f"{_fmt(match.marginal_partners)}")
    print(f"  other modes (contact, filter, sampling, joint space): {_fmt(np.sort_complex(match.extra))}")
    print(f"  matched within {100 * args.tolerance:.0f} % and no other mode unstable: {match.matched}")
    for diagnosis in getattr(result, "unstable_modes", []):
        print(f"  {diagnosis.summary()}")
    check = getattr(result, "jacobian_check", None)
    print(f"  {check.summary()}" if check is not None else
          "  Jacobian: central differences of the one-period map (no AutoDiffXd to check)")
    if args.plot:
        figure = eigenvalue_figure(match, title=f"{config.task}, {controller_mode.value}")
        figure.savefig(args.plot, dpi=110)
        plt.close(figure)
        print(f"  wrote {args.plot}")
    if args.json:
        payload = match.as_dict()
        payload.update({"gains": config.gains.as_lists(k, m, controller_mode), "mode": controller_mode.value,
                        "method": "continuous" if getattr(task, "continuous_plant", True) else "discrete",
                        "velocity_dim": k, "force_dim": m, "task": config.task,
                        "equilibrium_residual": result.equilibrium_residual, "wall_time": result.wall_time,
                        "jacobian_check": check.as_dict() if check is not None else {"used": "central differences"},
                        "unstable_modes": [d.as_dict() for d in getattr(result, "unstable_modes", [])]})
        Path(args.json).write_text(json.dumps(payload, indent=2))
        print(f"  wrote {args.json}")
    return 0 if match.matched else 1


def command_sweep(args):
    out = Path(args.out) if args.out else Path("runs") / f"sweep-{args.task}"
    try:
        spec = load_spec(path=args.grid)
        run = run_sweep(args.task, spec, out, scheduler=args.scheduler, workers=args.workers, resume=args.resume,
                        retry_failed=args.retry_failed, progress=not args.no_progress)
    except (SweepSpecError, ValueError) as error:
        raise SystemExit(f"drake-hybrid sweep: {error}") from None
    rows = read_results(run.results_path)
    stable = sum(1 for row in rows if row.get("stable"))
    print(f"{args.task}: {run.evaluated} of {run.points} points evaluated in {run.wall_time:.1f} s on {run.workers}; "
          f"{len(rows)} in the table, {stable} stable, {run.failures} with errors")
    print(f"  wrote {run.results_path}")
    if args.plot:
        for path in save_sweep_plots(rows, spec, out):
            print(f"  wrote {path}")
    return 0


def command_tasks(args):
    for name, task in TASKS.items():
        print(f"{name:18s} {task.description}")
    return 0


def make_parser():
    parser = argparse.ArgumentParser(prog="drake-hybrid", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    modes = [m.value for m in ControlMode]
    simulate = sub.add_parser("simulate", help="simulate a task (discrete 1 kHz plant and controller)")
    simulate.add_argument("task", choices=sorted(TASKS))
    simulate.add_argument("--duration", type=float, help="simulated time (s)")
    simulate.add_argument("--out", help="output directory (default ./runs/<task>)")
    simulate.add_argument("--mode", choices=modes)
    simulate.add_argument("--config", help="YAML scenario config (on top of the task's defaults)")
    simulate.add_argument("--option", action="append", metavar="KEY=VALUE",
                          help="a task option, e.g. --option chart=euler --option path=pole (sphere-polishing), "
                               "--option workpiece=sphere (grinding)")
    simulate.add_argument("--html", help="also write a self-contained Meshcat animation to this file")
    simulate.add_argument("--no-progress", action="store_true", help="no progress bar")
    simulate.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    simulate.set_defaults(func=command_simulate)
    analyze = sub.add_parser("analyze", help="linearize the closed loop; predicted vs. measured eigenvalues")
    analyze.add_argument("task", choices=sorted(TASKS))
    analyze.add_argument("--mode", choices=modes)
    analyze.add_argument("--config", help="YAML scenario config")
    analyze.add_argument("--option", action="append", metavar="KEY=VALUE", help="a task option (see simulate)")
    analyze.add_argument("--json", help="write the eigenvalues to this JSON file")
    analyze.add_argument("--plot", help="write the eigenvalue figure (predicted vs. linearized) to this PNG")
    analyze.add_argument("--tolerance", type=float, default=0.05, help="relative tolerance of the match")
    analyze.set_defaults(func=command_analyze)
    sweep = sub.add_parser("sweep", help="stability map / Monte Carlo sweep over config fields (Dask)")
    sweep.add_argument("task", choices=sorted(TASKS))
    sweep.add_argument("--grid", required=True, help="sweep spec YAML (see drake_hybrid/sweep_spec.py)")
    sweep.add_argument("--out", help="output directory (default ./runs/sweep-<task>)")
    sweep.add_argument("--scheduler", help="address of an existing Dask scheduler (e.g. tcp://host:8786)")
    sweep.add_argument("--workers", type=int, default=2,
                       help="worker processes of the local Dask cluster (default 2; 0 = serial, no Dask)")
    sweep.add_argument("--resume", action="store_true", help="continue the table in --out: run only missing points")
    sweep.add_argument("--retry-failed", action="store_true", help="with --resume, also re-run points with errors")
    sweep.add_argument("--plot", action="store_true", help="write the stability map / histograms (spec's map:)")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")
    sweep.set_defaults(func=command_sweep)
    tasks = sub.add_parser("tasks", help="list the tasks")
    tasks.set_defaults(func=command_tasks)
    return parser


def main(argv=None):
    args = make_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
