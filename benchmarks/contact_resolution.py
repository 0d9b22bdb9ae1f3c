"""Contact geometry and plant step at the cost their accuracy needs: a measured table per task.

    python benchmarks/contact_resolution.py [--tasks NAME ...] [--quick]

For each paper task (its default config and mode), a few settings of the pad's and the workpiece's
hydroelastic mesh resolution (``contact.pad_resolution``, ``contact.workpiece_resolution``) and of
the plant's time step, each simulated once and linearized once:

* accuracy: the worst velocity and force row errors after five design time constants (% of the
  command, summary.json's figures), the largest distance of the measured velocity and force from
  the finest setting's along the run (after contact; in % of the command, on the same 1 ms log
  times), and the designed eigenvalues' worst deviation (the continuous closed loop, or the
  crank's sampled map, as ``benchmarks/closed_loop.py`` linearizes them);
* cost: the plant alone's real-time factor replaying that run's torques (``closed_loop.plant_alone_rtf``),
  the closed loop's, and the seconds to build the simulation's diagram (the meshes are made then).

Writes ``results/contact_resolution.json`` and ``docs/contact_resolution.md`` (the table and the
choice per task). One run on the shared machine: the real-time factors carry its load; compare
within a task's rows.
"""

import argparse
import json
import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from closed_loop import _linearization, plant_alone_rtf  # noqa: E402

from drake_hybrid.control import fast_compile  # noqa: E402
from drake_hybrid.experiments.simulation import simulate  # noqa: E402
from drake_hybrid.scenario.builder import build_scenario  # noqa: E402
from drake_hybrid.tasks.registry import get_task

DOC = HERE.parent / "docs" / "contact_resolution.md"
MM = 1e-3
# (label, changes to the default config). The first row is the reference: the finest meshes at the task's own
# step (the crank's: the finest step); a row with a finer step shows what the step changes.
SETTINGS = {
    "window-washing": [
        ("pad 1.5 mm", {"contact.pad_resolution": 1.5 * MM}),
        ("pad 3 mm (default)", {}),
        ("pad 5 mm", {"contact.pad_resolution": 5 * MM}),
        ("pad 8 mm", {"contact.pad_resolution": 8 * MM}),
        ("pad 3 mm, step 0.5 ms", {"plant.time_step": 0.5 * MM}),
    ],
    "grinding": [
        ("pad 1.5 mm", {"contact.pad_resolution": 1.5 * MM}),
        ("pad 3 mm (default)", {}),
        ("pad 5 mm", {"contact.pad_resolution": 5 * MM}),
        ("pad 8 mm", {"contact.pad_resolution": 8 * MM}),
        ("pad 3 mm, step 0.5 ms", {"plant.time_step": 0.5 * MM}),
    ],
    "sphere-polishing": [
        ("pad 1.5 mm, sphere 2 mm", {"contact.pad_resolution": 1.5 * MM, "contact.workpiece_resolution": 2 * MM}),
        ("pad 3 mm, sphere 3 mm (default)", {}),
        ("pad 3 mm, sphere 5 mm", {"contact.workpiece_resolution": 5 * MM}),
        ("pad 3 mm, sphere 10 mm", {"contact.workpiece_resolution": 10 * MM}),
        ("pad 5 mm, sphere 5 mm", {"contact.pad_resolution": 5 * MM, "contact.workpiece_resolution": 5 * MM}),
        ("pad 5 mm, sphere 10 mm", {"contact.pad_resolution": 5 * MM, "contact.workpiece_resolution": 10 * MM}),
        ("pad 3 mm, sphere 3 mm, step 0.5 ms", {"plant.time_step": 0.5 * MM}),
    ],
    "crank-turning": [                               # the pad is welded to the handle: no contact meshes
        ("step 0.25 ms", {"plant.time_step": 0.25 * MM}),
        ("step 0.5 ms (default)", {}),
        ("step 1 ms", {"plant.time_step": 1.0 * MM}),
    ],
}
QUICK = {"window-washing": [0, 1, 2], "grinding": [0, 1, 2], "sphere-polishing": [0, 1, 4], "crank-turning": [1, 2]}


def configure(task_name, changes):
    config = get_task(task_name).default_config()
    for path, value in changes.items():
        section, name = path.split(".")
        setattr(getattr(config, section), name, value)
    return config


def _after_contact(log, summary):
    return log["t"] >= summary.contact_time + 5 * summary.design_time_constant


def _distance(log, reference, key, scale, mask):
    """max |x - x_ref| over the masked samples, in % of ``scale`` (the rows' command size)."""
    n = min(len(log["t"]), len(reference["t"]))
    difference = np.abs(np.asarray(log[key][:n]) - np.asarray(reference[key][:n]))[mask[:n]]
    return float(100.0 * difference.max() / scale) if difference.size else None


def measure_setting(task_name, label, changes, reference=None):
    config = configure(task_name, changes)
    start = time.perf_counter()
    build_scenario(config, with_loggers=False)
    build_s = time.perf_counter() - start
    run = simulate(config)
    log, summary = run.log, run.summary
    entry = {"label": label, "changes": changes, "build_s": build_s, "closed_loop_rtf": summary.real_time_factor,
             "velocity_error_percent": summary.max_velocity_error_percent_after_5_time_constants,
             "force_error_percent": summary.max_force_error_percent_after_5_time_constants}
    entry["plant_rtf"], _, entry["replay_drift"] = plant_alone_rtf(config, "replay", log)
    entry["plant_rtf_cpu"] = plant_alone_rtf(config, "replay", log, clock=time.process_time)[0]
    linear = _linearization(config)
    entry["eigenvalue_deviation_percent"] = linear["eigenvalue_deviation_percent"]
    entry["eigenvalues_matched"] = linear["eigenvalues_matched_within_5_percent"]
    if reference is not None:
        mask = _after_contact(log, summary)
        scales = summary.command_scales
        entry["velocity_from_finest_percent"] = _distance(log, reference, "velocity", scales["speed"], mask)
        entry["force_from_finest_percent"] = _distance(log, reference, "force", scales["force"], mask)
    return entry, log


def measure(tasks, quick=False, log=print):
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "load_average_at_start":
               os.getloadavg(), "cores": os.cpu_count(), "tasks": {}}
    for task_name in tasks:
        settings = SETTINGS[task_name]
        if quick:
            settings = [settings[i] for i in QUICK[task_name]]
        rows, reference = [], None
        for label, changes in settings:
            entry, run_log = measure_setting(task_name, label, changes, reference)
            if reference is None:
                reference = run_log
            rows.append(entry)
            log(f"  {task_name}, {label}: " + ", ".join(f"{k} {v:.4g}" for k, v in entry.items()
                                                        if isinstance(v, float)))
        results["tasks"][task_name] = rows
    return results


def _fmt(value, digits=3):
    if value is None:
        return "-"
    return f"{value:.{digits}g}"


def markdown(results):
    lines = ["# Contact meshes and plant step: accuracy against cost", "",
             "Generated by `python benchmarks/contact_resolution.py` "
             f"({results['date']}, {results['cores']} shared cores, load average at the start "
             f"{results['load_average_at_start'][0]:.1f}). Each task's default config and mode, one setting "
             "changed per row: the pad's and the workpiece's hydroelastic mesh resolution hints "
             "(`contact.pad_resolution`, `contact.workpiece_resolution`) and the plant's time step (the "
             "controller stays at 1 kHz). Accuracy: the worst velocity and force row errors after five design "
             "time constants (% of the command), the largest distance of the run's measured velocity and force "
             "from the first row's (the finest meshes) after contact (% of the command), the designed "
             "eigenvalues' worst "
             "deviation (the continuous closed loop; the crank's sampled map). Cost: the plant alone's "
             "real-time factor replaying the run's torques, by this process's CPU time (what the machine's load "
             "distorts least) and by the wall clock, the closed loop's, and the seconds to build the diagram "
             "(the meshes are made then). Wall-clock figures depend on the machine's load: compare within a "
             "task, and prefer the CPU-time column.", ""]
    for task_name, rows in results["tasks"].items():
        lines += [f"## {task_name}", "",
                  "| setting | velocity err. % | force err. % | velocity from finest % | force from finest % | "
                  "eigenvalue dev. % | plant-alone RTF (CPU time) | plant-alone RTF (wall) | closed-loop RTF (wall) | "
                  "build s |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for row in rows:
            lines.append(f"| {row['label']} | {_fmt(row['velocity_error_percent'])} | "
                         f"{_fmt(row['force_error_percent'])} | {_fmt(row.get('velocity_from_finest_percent'))} | "
                         f"{_fmt(row.get('force_from_finest_percent'))} | {_fmt(row['eigenvalue_deviation_percent'])}"
                         f"{'' if row['eigenvalues_matched'] else ' (not matched)'} | {_fmt(row['plant_rtf_cpu'])} | "
                         f"{_fmt(row['plant_rtf'])} | "
                         f"{_fmt(row['closed_loop_rtf'])} | {_fmt(row['build_s'], 2)} |")
        lines.append("")
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(SETTINGS))
    parser.add_argument("--quick", action="store_true", help="three settings or fewer per task")
    parser.add_argument("--json", type=Path, default=HERE / "results" / "contact_resolution.json")
    parser.add_argument("--doc", type=Path, default=DOC, help="the markdown table (default docs/contact_resolution.md)")
    args = parser.parse_args()
    fast_compile.set_policy("foreground")
    results = measure(args.tasks, args.quick)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1, default=float) + "\n")
    print(f"wrote {args.json}")
    if args.doc:
        write_doc(results, args.doc)
        print(f"wrote {args.doc}")


def write_doc(results, path=DOC):
    """The table into ``path``, keeping its hand-written "## Choice" section."""
    text = "\n".join(markdown(results)) + "\n"
    if path.exists() and "## Choice" in path.read_text():
        text += "\n## Choice" + path.read_text().split("## Choice", 1)[1]
    path.write_text(text)


if __name__ == "__main__":
    main()
