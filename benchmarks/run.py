"""Performance benchmarks of drake_hybrid against Drake's own controller and plant: the one command.

    python benchmarks/run.py [--quick] [--tasks NAME ...] [--skip PART ...] [--out DIR]

Measures, in one process (and the fresh processes and venv some parts need), and writes
``results.json`` and ``RESULTS.md`` next to this file (or in ``--out``):

1. controller tick per robot (planar 3R, UR5e, Franka Panda): median and 95th
   percentile of one fresh float evaluation of the HybridController's torque,
   against Drake's C++ InverseDynamicsController on the same plant (tick.py),
   and against the Python floor: a controller that makes only the Drake calls
   the law needs and reads its ports (python_floor.py; part ``floor``);
2. per task in ``drake_hybrid.tasks.registry.TASKS``: the 1 kHz closed loop's
   real-time factor against the plant alone (and against the floor's closed loop,
   a Python update that only reads the state and the contact results); accuracy per
   mode; linearization wall time; the task's own controller tick (closed_loop.py);
3. scaling: tick against the number of joints (3, 4, 6, 7) and constraint rows
   (m = 1..5 on the UR5e and the Panda);
4. per task, inside the closed-loop simulation: a step's time by part (the law, the sensor, the
   contact results it reads, the source, the controller's update, the rest), the law's cost per
   evaluation there and alone (in_simulation.py);
5. the fast path's first tick in fresh processes, with an empty numba cache and cached (part ``compile``);
6. the main job's first run after ``pip install .`` in a fresh venv, warm, and the command line's
   help (first_run.py; part ``first_run``: a few minutes, most of it the install);
7. sweep throughput: points per minute serially, on 1, 2 and 4 local Dask workers and an external
   scheduler on 127.0.0.1; a point's time by stage; a fresh worker's cost (sweep_throughput.py;
   part ``sweep``);
8. contact meshes and plant step, accuracy against cost per task (contact_resolution.py; part
   ``resolution``, which also rewrites docs/contact_resolution.md's table);
9. the controller side's tick at 1 kHz on the replayed Panda: cost per tick by part, deadline misses by
   cause, with and without the real-time settings (realtime_tick.py; part ``realtime``, about 5 minutes).

Targets (docs/performance.md): tick <= 4x the InverseDynamicsController on the UR5e,
the Panda and the planar 3R; closed-loop RTF >= 0.8x plant alone for every task with every accuracy
figure held (<= 1 % planar, <= 2 % 6-DOF, eigenvalues within 5 %); the first run <= 30 s, warm <= 5 s
beyond its simulated work, both helps < 1 s. The machine is shared and noisy: ratios are taken
within one run, interleaved where possible, and RESULTS.md says how loaded the machine was.
Takes about 40 minutes on 2 loaded cores (``--quick``: fewer samples, the quick contact table;
``--skip first_run sweep resolution``: about 5 minutes).
"""

import argparse
import json
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import closed_loop  # noqa: E402
import contact_resolution  # noqa: E402
import first_run  # noqa: E402
import in_simulation  # noqa: E402
import python_floor  # noqa: E402
import realtime_tick  # noqa: E402
import sweep_throughput  # noqa: E402
import tick  # noqa: E402

from drake_hybrid.tasks.registry import TASKS

ROBOTS = ("planar-3r", "ur5e", "panda")
SCALING_JOINTS = ("planar-3r", "planar-4r", "ur5e", "panda")
SCALING_ROWS = (1, 2, 3, 4, 5)
TARGETS = {"tick_ratio": 4.0, "rtf_ratio": 0.8, "accuracy_percent_planar": 1.0,
           "accuracy_percent_6dof": 2.0, "eigenvalue_deviation_percent": 5.0, "first_run_s": 30.0,
           "warm_beyond_simulated_work_s": 5.0, "help_s": 1.0}
PARTS = ("floor", "compile", "first_run", "sweep", "resolution", "realtime")
# Tasks whose tracking errors are the point of the task, not a defect: friction makes velocity/force
# stall and impedance/force yield by its impedance (docs/impedance.md measures them).
ACCURACY_NOT_APPLICABLE = {"grinding": "friction task: velocity/force stalls, impedance/force yields by design "
                                       "(docs/impedance.md)"}


def machine():
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import importlib.metadata

    import numpy

    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "drake": importlib.metadata.version("drake"), "numpy": numpy.__version__,
            "platform": platform.platform(), "load_average_at_start": load}


def _fmt(value, digits=3):
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def targets(results):
    """Which performance targets this run meets (True/False per target, with the figure)."""
    verdict = {}
    first = results.get("first_run")
    if first:
        verdict["first run after pip install, wall s <= 30"] = {
            "value": first["first_run"]["wall_s"], "met": first["first_run"]["wall_s"] <= TARGETS["first_run_s"]}
        beyond = max(run["beyond_simulated_work_s"] for run in first["warm_runs"])
        verdict["warm run, s beyond its simulated work <= 5"] = {
            "value": beyond, "met": beyond <= TARGETS["warm_beyond_simulated_work_s"]}
        for key, command in (("help_s", "drake-hybrid --help"), ("simulate help_s", "drake-hybrid simulate --help")):
            verdict[f"{command}, s < 1"] = {"value": first[key], "met": first[key] < TARGETS["help_s"]}
    for name, target in (results.get("realtime") or {}).get("targets", {}).items():
        verdict[f"controller side's tick at 1 kHz (replayed Panda), {name}"] = {"value": target["value"] * 1e3,
                                                                              "met": target["met"]}
    for name, r in results["robots"].items():
        ratio = r["tick_ratio"]["median"]
        verdict[f"{name}: tick <= 4x IDC (median)"] = {"value": ratio, "met": ratio <= TARGETS["tick_ratio"]}
    for name, task in results["tasks"].items():
        verdict[f"{name}: closed-loop RTF >= 0.8x plant alone"] = {
            "value": task["rtf_ratio"], "met": task["rtf_ratio"] >= TARGETS["rtf_ratio"]}
        if "cpu_rtf_ratio" in task:
            verdict[f"{name}: the same by CPU time"] = {
                "value": task["cpu_rtf_ratio"], "met": task["cpu_rtf_ratio"] >= TARGETS["rtf_ratio"]}
        planar = task["tick"].get("task_size", 6) == 3
        limit = TARGETS["accuracy_percent_planar"] if planar else TARGETS["accuracy_percent_6dof"]
        for mode, entry in task["modes"].items():
            # The velocity and force errors after five design time constants (the final ones included).
            errors = [entry.get("max_velocity_error_percent_after_5_time_constants"),
                      entry.get("max_force_error_percent_after_5_time_constants")]
            label = f"{name} {mode}: errors after 5 tau <= {limit:g} %"
            if name in ACCURACY_NOT_APPLICABLE:
                verdict[label] = {"value": max(errors) if None not in errors else None, "met": "n/a",
                                  "why": ACCURACY_NOT_APPLICABLE[name]}
            elif None in errors or "simulation_error" in entry:
                verdict[label] = {"value": None, "met": False}
            else:
                worst = max(errors)
                verdict[label] = {"value": worst, "met": worst <= limit}
            deviation = entry.get("eigenvalue_deviation_percent")
            verdict[f"{name} {mode}: eigenvalues within 5 %"] = {
                "value": deviation,
                "met": deviation is not None and deviation <= TARGETS["eigenvalue_deviation_percent"]
                and not entry.get("unstable_extra_modes")}
    return verdict


def _floor_lines(results):
    """The tick and the closed loop against the Python floor (python_floor.py)."""
    floor = results.get("floor")
    if not floor:
        return []
    lines = ["", "## Against the Python floor", "",
             "A Python controller that only makes the Drake calls the law needs and reads its five ports "
             "(no law), timed interleaved with ours and the IDC; and a closed loop whose Python update only "
             "reads the state and the contact results (no law, sensor, source or logger), against the plant "
             "alone (`benchmarks/python_floor.py`).", "",
             "| robot | ours us | floor us | IDC us | ours / IDC | floor / IDC | left between them, us |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in floor["ticks"].items():
        lines.append(f"| {name} | {r['controller_us']:.1f} | {r['floor_us']:.1f} | {r['idc_us']:.1f} | "
                     f"{r['controller_ratio']:.1f} | {r['floor_ratio']:.1f} | "
                     f"{r['controller_us'] - r['floor_us']:.1f} |")
    lines += ["", "| task | closed loop / plant alone | floor closed loop / plant alone |", "|---|---:|---:|"]
    for name, r in floor["closed_loops"].items():
        lines.append(f"| {name} | {r['ratio']['closed_loop']:.2f} | {r['ratio']['floor_sampled']:.2f} |")
    return lines


def _first_run_lines(results):
    first = results.get("first_run")
    if not first:
        return []
    run = first["first_run"]
    lines = ["", "## The main job's first run (`benchmarks/first_run.py`)", "",
             f"A fresh venv, `pip install .` ({first['install_s']:.0f} s, not counted), then "
             f"`drake-hybrid simulate window-washing` timed from the command to its last line: first "
             f"{run['wall_s']:.1f} s ({run['simulated_work_s']:.1f} s of it the simulated work, the generic law: "
             f"{_fmt(run['generic_law'])}; numba compiled the fast law in the background, done "
             f"{first['compile_job_done_s_after_install']:.0f} s after the install), warm "
             + ", ".join(f"{r['wall_s']:.1f} s ({r['beyond_simulated_work_s']:.1f} s beyond the simulated work)"
                         for r in first["warm_runs"])
             + f"; `drake-hybrid --help` {first['help_s']:.2f} s, `drake-hybrid simulate --help` "
             f"{first['simulate help_s']:.2f} s. Load average {first['load_average_at_start'][0]:.1f} at its start.",
             "", "Stages of the first run (s): " + ", ".join(f"{k} {v}" for k, v in run["stages_s"].items()),
             "", "Stages of the last warm run (s): "
             + ", ".join(f"{k} {v}" for k, v in first["warm_runs"][-1]["stages_s"].items())]
    return lines


def _sweep_lines(results):
    sweep = results.get("sweep")
    if not sweep:
        return []
    lines = ["", "## Sweep throughput (`benchmarks/sweep_throughput.py`)", "",
             f"{sweep['points']} points of the window task ({sweep['duration']:g} s simulated, a continuous and a "
             "sampled-loop linearization each); the cluster's start-up and its workers' warm-up are not counted.", "",
             "| where | points / min | vs serial | CPU / wall in the points | start-up s | load before |",
             "|---|---:|---:|---:|---:|---:|"]
    for label, run in sweep["runs"].items():
        lines.append(f"| {label} | {run['points_per_minute']:.1f} | {sweep['scaling'][label]:.2f} | "
                     f"{run['cpu_share']:.2f} | {run['cluster_startup']:.1f} | {run['load_before']:.1f} |")
    lines += ["", "A point's seconds by stage: " + ", ".join(f"{k} {v:.2f}" for k, v in
                                                           sweep["point_breakdown_s"].items()) + "."]
    for label, entry in sweep["fresh_worker"].items():
        lines.append(f"A fresh worker, numba cache {label.split()[0]}: import {entry['import_s']:.1f} s, first point "
                     f"{entry['first_point_s']:.1f} s, second {entry['second_point_s']:.1f} s"
                     + (f"; its background compile done after {entry['compile_job_done_after_s']:.0f} s"
                        if "compile_job_done_after_s" in entry else "") + ".")
    return lines


def markdown(results):
    m = results["machine"]
    end = results.get("load_average_at_end")
    lines = ["# drake_hybrid performance benchmarks", "",
             f"Generated by `python benchmarks/run.py` on {results['date']} in {results['wall_s']:.0f} s.", "",
             f"Machine: {m['cpu']}, {m['cores']} cores (shared; load average at start "
             f"{_fmt(m['load_average_at_start'] and m['load_average_at_start'][0])}"
             + (f", at the end {end[0]:.1f}" if end else "") + f"), Python {m['python']}, "
             f"Drake {m['drake']}, numpy {m['numpy']}. Ratios are within this run; the timed evaluations of "
             "the two controllers are interleaved sample by sample. On a shared machine a load average above "
             "the core count means other jobs took CPU time from these measurements: absolute times are then "
             "inflated (and the real-time factors lowered) by up to that factor, and a quiet machine gives "
             "better absolute figures; ratios measured within one run, interleaved, hold better.", "",
             "## Controller tick (one fresh float evaluation of the torque output)", "",
             "| robot | n | m | controller us (median / p95 / p99 / max) | generic law us | sampled update us | "
             "IDC us (median / p95) | ratio (median / p95) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in results["robots"].items():
        c, i, u = r["controller_tick_us"], r["idc_tick_us"], r["sampled_update_us"]
        g = r.get("generic_tick_us", {}).get("median_us", float("nan"))
        lines.append(f"| {name} | {r['joints']} | {r['force_rows']} | {c['median_us']:.1f} / {c['p95_us']:.1f} / "
                     f"{c.get('p99_us', float('nan')):.1f} / {c.get('max_us', float('nan')):.0f} | {g:.1f} | "
                     f"{u['median_us']:.1f} | {i['median_us']:.1f} / {i['p95_us']:.1f} | "
                     f"{r['tick_ratio']['median']:.1f} / {r['tick_ratio']['p95']:.1f} |")
    compile_ = results.get("compile")
    if compile_:
        lines += ["", "Fast path (control/fast_law.py, numba) first tick, in fresh processes: "
                  + "; ".join(f"{run}: " + ", ".join(f"{name} {v['first_tick_s']:.2f} s (compile or load "
                                                          f"{v['compile_or_load_s']:.2f} s)" for name, v in r.items())
                              for run, r in compile_.items())
                  + ". Cold: empty numba cache, the first controller compiles the kernels and its constraint, a "
                  "second constraint only its generated module; cached: the same processes again. Generic law: the "
                  "same controller with `fast_law=False` (control/law.py), timed in its own loop. The p99 and max "
                  "of a shared, loaded machine are preemptions by other processes, not the law."]
    lines += ["", "Robots: " + "; ".join(f"**{k}** {v['description']}" for k, v in results["robots"].items()) + ".",
              "IDC: Drake's C++ `InverseDynamicsController` (with reference acceleration) on the same plant. "
              "Sampled update: the 1 kHz controller's periodic discrete update (law + integrals), timed in its own "
              "loop. On a loaded machine the 95th percentiles include preemption by other processes, which hits a "
              "200 us call far more often than a 10 us one; the medians are the comparison.", "",
              "## Simulation speed (1 kHz closed loop vs the plant alone)", "",
              "| task | closed-loop RTF | plant alone, replayed torques | ratio | by CPU time: closed loop / plant "
              "alone / ratio | plant, static torque | plant, zero torque | replay drift (rad) |",
              "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, t in results["tasks"].items():
        lines.append(f"| {name} | {t['rtf']:.3g} | {t['plant_rtf']:.3g} | {t['rtf_ratio']:.2f} | "
                     f"{t['cpu_rtf']:.3g} / {t['plant_cpu_rtf']:.3g} / {t['cpu_rtf_ratio']:.2f} | "
                     f"{t['plant_rtf_static_torque']:.3g} | {t['plant_rtf_zero_torque']:.3g} | "
                     f"{_fmt(t['replay_drift'])} |")
    lines += ["", "RTF = simulated / wall seconds of `AdvanceTo` (by CPU time: simulated / this process's CPU seconds, "
              "which the other jobs of a shared machine distort far less). Closed loop: "
              "`drake_hybrid.experiments.simulation.simulate` "
              "(plant, sampled controller, wrench sensor, source, loggers). Plant alone: the same plant and contact "
              "replaying the closed loop's logged torques (same motion, same contact; see closed_loop.py). "
              "Medians of the repeats.", "",
              "## Inside the simulation: one closed-loop step by part", ""]
    lines += in_simulation.table(results["in_simulation"])
    lines += ["", "Microseconds per plant step of the task's default closed loop (`benchmarks/in_simulation.py`, "
              f"{_fmt(results['settings'].get('in_simulation_s'))} simulated seconds each, after 0.05 s): each Python "
              "system's calculation timed by a wrapper, exclusive of the calls nested in it. Law: the controller's "
              "cache calculation (state, force elements, the compiled law and its Drake calls); law isolated: the "
              "same calculation at the same state timed alone in a loop, so the difference is what the contact "
              "solver's eviction of the CPU caches costs it. Contact results: the plant's sampled contact results "
              "(the crank's wrist sensor: its reaction forces) read by the sensor once a step, a read of the step's "
              "own solve (docs/drake_notes.md, \"Sampled plant output ports\"). Rest: the plant's step with its one "
              "contact solve, the simulator, the loggers.", "",
              "## Accuracy and linearization, per task and mode", "",
              "| task | mode | final velocity error % | final force error % | max after 5 tau (v / F) % | "
              "max / final abs C | eigenvalue deviation % | matched | Linearize s | whole linearization s |",
              "|---|---|---:|---:|---:|---:|---:|---|---:|---:|"]
    for name, t in results["tasks"].items():
        for mode, e in t["modes"].items():
            if "simulation_error" in e:
                lines.append(f"| {name} | {mode} | simulation failed: {e['simulation_error']} ||||||||")
                continue
            lines.append(
                f"| {name} | {mode} | {_fmt(e['final_velocity_error_percent'])} | {_fmt(e['final_force_error_percent'])} | "
                f"{_fmt(e['max_velocity_error_percent_after_5_time_constants'])} / "
                f"{_fmt(e['max_force_error_percent_after_5_time_constants'])} | "
                f"{_fmt(e['max_constraint_residual'])} / {_fmt(e['final_constraint_residual'])} | "
                f"{_fmt(e.get('eigenvalue_deviation_percent'))} | "
                f"{_fmt(e.get('eigenvalues_matched_within_5_percent'))} | {_fmt(e.get('linearize_wall_s'))} | "
                f"{_fmt(e.get('linearize_total_wall_s'))} |")
    lines += ["", "Errors in % of the command's size (|r-dot_pd|, |F_d|). C is in the constraint's units (m for "
              "the window): its residual is mostly the compliant pad's penetration at the commanded force. "
              "Eigenvalue deviation: the largest |measured - designed| / |designed| over the designed "
              "eigenvalues of the continuous closed loop (`analysis.linearize_continuous`), or for the crank, "
              "whose SAP weld exists only in discrete time, of the sampled loop's one-period map "
              "(`analysis.linearize_discrete`; its spin row is moved by the handle's inertia, which the "
              "paper's massless constraint leaves out, and in impedance mode also by the tool's inertia that the "
              "wrist sensor reports: both predicted within 2 % in tests/test_six_dof.py, docs/drake_notes.md). The crank's plant-alone replay "
              "drifts (the open-loop replay does not reproduce the closed loop's motion; not investigated), but "
              "its plant costs the same with replayed, static or zero torque (about 7x real time), so the RTF "
              "ratio stands.", "",
              "## Scaling", "", "Tick against the number of joints n (velocity-force mode):", "",
              "| robot | n | d | m | controller us | IDC us | ratio |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in results["scaling"]["joints"].items():
        lines.append(f"| {name} | {r['joints']} | {r['task_size']} | {r['force_rows']} | "
                     f"{r['controller_tick_us']['median_us']:.1f} | {r['idc_tick_us']['median_us']:.1f} | "
                     f"{r['tick_ratio']['median']:.1f} |")
    lines += ["", "Tick against the constraint rows m (PoseChart, kernel E_p; rows z, a_x, a_y, x, y):", "",
              "| robot | n | m | controller us | IDC us | ratio |", "|---|---:|---:|---:|---:|---:|"]
    for r in results["scaling"]["rows"]:
        lines.append(f"| {r['robot']} | {r['joints']} | {r['force_rows']} | {r['controller_tick_us']['median_us']:.1f} | "
                     f"{r['idc_tick_us']['median_us']:.1f} | {r['tick_ratio']:.1f} |")
    lines += ["", "Per-task controllers (built by the task's scenario, at its start):", "",
              "| task | n | m | controller us | IDC us | ratio |", "|---|---:|---:|---:|---:|---:|"]
    for name, t in results["tasks"].items():
        k = t["tick"]
        lines.append(f"| {name} | {k['joints']} | {k['force_rows']} | {k['controller_tick_us']:.1f} | "
                     f"{k['idc_tick_us']:.1f} | {k['tick_ratio']:.1f} |")
    lines += _floor_lines(results) + _first_run_lines(results) + _sweep_lines(results)
    if results.get("realtime"):
        lines += [""] + realtime_tick.markdown_lines(results["realtime"])
    lines += ["", "## Targets", "", "| target | this run | met |", "|---|---:|---|"]
    for name, v in results["targets"].items():
        met = v["met"] if v["met"] != "n/a" else f"n/a: {v['why']}"
        lines.append(f"| {name} | {_fmt(v['value'])} | {_fmt(met)} |")
    lines += ["", "Where the time goes and what to change: `benchmarks/PROFILE.md`.", ""]
    return "\n".join(lines)


def _save(part, name):
    """A part's figures also in results/NAME (what its own script writes when run alone)."""
    (HERE / "results").mkdir(exist_ok=True)
    (HERE / "results" / name).write_text(json.dumps(part, indent=1, default=float) + "\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples and repeats (about a minute)")
    parser.add_argument("--tasks", nargs="+", default=sorted(TASKS), help="tasks to measure (default: all)")
    parser.add_argument("--out", type=Path, default=HERE, help="folder for results.json and RESULTS.md")
    parser.add_argument("--skip", nargs="+", default=[], choices=PARTS, help="parts not to measure")
    args = parser.parse_args(argv)
    samples, repeats, row_samples = (500, 1, 300) if args.quick else (3000, 3, 1500)
    in_simulation_s = 0.3 if args.quick else 1.0
    start = time.perf_counter()
    results = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "machine": machine(),
               "settings": {"tick_samples": samples, "repeats": repeats, "row_samples": row_samples,
                            "in_simulation_s": in_simulation_s},
               "robots": {}, "tasks": {}, "scaling": {"joints": {}, "rows": []}, "in_simulation": {}}
    print(f"machine: {results['machine']['cpu']}, {results['machine']['cores']} cores, "
          f"Drake {results['machine']['drake']}")
    for name in SCALING_JOINTS:
        r = tick.measure_robot(name, samples=samples, warmup=samples // 10)
        results["scaling"]["joints"][name] = r
        if name in ROBOTS:
            results["robots"][name] = r
        print(f"tick {name:10s} n={r['joints']} controller {r['controller_tick_us']['median_us']:7.1f} us "
              f"(p95 {r['controller_tick_us']['p95_us']:.1f}), IDC {r['idc_tick_us']['median_us']:5.1f} us, "
              f"ratio {r['tick_ratio']['median']:.1f}")
    if "compile" not in args.skip:
        results["compile"] = tick.compile_times()
        print(f"fast-law first tick: cold {results['compile']['cold']}, cached {results['compile']['cached']}")
    if "floor" not in args.skip:
        results["floor"] = {
            "ticks": {name: python_floor.measure_tick_floor(name, samples) for name in ROBOTS},
            "closed_loops": {name: python_floor.measure_rtf_floor(name, repeats) for name in args.tasks}}
        print("floor: " + ", ".join(f"{k} {v['floor_ratio']:.1f}x" for k, v in results["floor"]["ticks"].items())
              + "; closed loops " + ", ".join(f"{k} {v['ratio']['floor_sampled']:.2f}"
                                              for k, v in results["floor"]["closed_loops"].items()))
    for arm in ("ur5e", "panda"):
        for rows in SCALING_ROWS:
            r = tick.measure_rows(arm, rows, samples=row_samples, warmup=row_samples // 10)
            results["scaling"]["rows"].append(r)
            print(f"rows {arm:6s} m={rows} controller {r['controller_tick_us']['median_us']:7.1f} us, "
                  f"ratio {r['tick_ratio']:.1f}")
    for name in args.tasks:
        print(f"task {name}")
        results["tasks"][name] = closed_loop.measure_task(name, repeats=repeats, tick_samples=samples,
                                                          log=lambda line: print(line, flush=True))
        t = results["tasks"][name]
        print(f"  rtf {t['rtf']:.3g}, plant alone {t['plant_rtf']:.3g}, ratio {t['rtf_ratio']:.2f}")
    for name in args.tasks:
        results["in_simulation"][name] = in_simulation.measure_task(name, duration=in_simulation_s)
        r = results["in_simulation"][name]
        print(f"in simulation {name}: step {r['step_us']:.0f} us, law {r['law_us']:.1f} us per evaluation "
              f"(alone {r['law_isolated_us']:.1f}), {100 * r['law_share_of_step']:.0f} % of the step")
    if "first_run" not in args.skip:
        print("first run")
        results["first_run"] = first_run.measure()
        _save(results["first_run"], "first_run.json")
    if "sweep" not in args.skip:
        print("sweep throughput")
        results["sweep"] = sweep_throughput.measure(0.5, HERE / "results")
    if "realtime" not in args.skip:
        print("real-time tick")
        results["realtime"] = realtime_tick.measure(seconds=2.0 if args.quick else 10.0, compare=True)
        _save(results["realtime"], "realtime_tick.json")
    if "resolution" not in args.skip:
        print("contact meshes and plant step")
        results["resolution"] = contact_resolution.measure(args.tasks, quick=args.quick)
        _save(results["resolution"], "contact_resolution.json")
        contact_resolution.write_doc(results["resolution"])
    results["load_average_at_end"] = os.getloadavg()
    results["targets"] = targets(results)
    results["wall_s"] = time.perf_counter() - start
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=2))
    text = markdown(results)
    (args.out / "RESULTS.md").write_text(text)
    print()
    print(text)
    return results


if __name__ == "__main__":
    main()
