"""Sweep throughput: points per minute serially, on 1, 2 and 4 local Dask workers and on an external
scheduler on 127.0.0.1; where a point's time goes; what a fresh worker pays before its first point.

    python benchmarks/sweep_throughput.py [--duration S] [--out DIR]

The same sweep (window washing, pad modulus x K_fp x control period: each point a simulation plus
the continuous and the sampled-loop linearizations, ``experiments.sweep_point.evaluate_point``) runs
serially in this process (no Dask), on a LocalCluster of 1, 2 and 4 single-threaded worker
processes, and on a ``dask scheduler`` with ``dask worker --nworkers 2`` started here on
127.0.0.1. Each cluster is started and its workers import drake_hybrid and load the compiled law
before the clock starts (that start-up is reported on its own), so a rate is the steady throughput.
Each run also reports the CPU time over the wall time inside its points (1.0 when each worker had
a core to itself) and the load average before it: on a shared 2-core machine 2 workers fall short
of twice one by that contention, and 4 workers cannot beat 2.

Where a point's time goes: the stages of ``evaluate_point`` timed on serial points (config, the
simulation's build, start and initialization, the simulated run, each linearization).

A fresh worker: a new process that imports what a point needs and evaluates two points, with
numba's cache warm (the compiled law loads) and empty (the first point runs the generic law while
a background job compiles it: control/fast_compile.py), and how long that job takes.

Writes ``sweep_throughput.json`` and ``.png`` in ``--out`` (default benchmarks/results).
"""

import argparse
import json
import logging
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cloudpickle

from drake_hybrid.core.progress import Stages
from drake_hybrid.experiments.sweep import run_sweep, sweep_points
from drake_hybrid.experiments.sweep_point import evaluate_point
from drake_hybrid.experiments.sweep_results import read_results
from drake_hybrid.experiments.sweep_spec import load_spec

TASK = "window-washing"
SPEC = """
base: {{duration: {duration}}}
parameters:
  contact.pad_modulus: {{values: [5.0e6, 1.0e8]}}
  gains.force_proportional: {{values: [0.25, 0.5, 0.75]}}
  control_period: {{values: [0.001, 0.004]}}
"""
# The workers do not have this folder on their path: its functions (warm_up) travel by value.
cloudpickle.register_pickle_by_value(sys.modules[__name__])
STAGES = {"config": "config", "build": "building the diagram", "start": "solving the start",
          "initialize": "initializing the simulator", "simulation": "simulation",
          "continuous linearization": "continuous linearization", "discrete linearization": "discrete linearization"}


def warm_up(task=TASK):
    """What a worker does once: import the sweep and load the compiled law (one short point)."""
    started = time.perf_counter()
    import drake_hybrid.experiments.sweep  # noqa: F401
    from drake_hybrid.experiments.simulation import simulate
    from drake_hybrid.tasks.registry import get_task

    config = get_task(task).default_config()
    config.duration = 0.01
    simulate(config)
    return time.perf_counter() - started


def _rate(points, wall):
    return 60.0 * points / wall


def _cpu_share(rows):
    return sum(row["cpu_time"] for row in rows) / sum(row["wall_time"] for row in rows)


def timed_run(spec, points, workers=0, scheduler=None):
    """{wall_time, cluster_startup, points_per_minute, errors, cpu_share, load_before}."""
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as out:
        startup, client, cluster = 0.0, None, None
        if workers or scheduler:
            from distributed import Client, LocalCluster

            start = time.perf_counter()
            if scheduler is None:
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=logging.ERROR)
                client = Client(cluster)
            else:
                client = Client(scheduler, timeout=60)
            client.run(warm_up)
            startup = time.perf_counter() - start
        try:
            start = time.perf_counter()
            address = scheduler or (cluster.scheduler_address if cluster else None)
            run_sweep(TASK, spec, out, scheduler=address, workers=0, progress=False)
            wall = time.perf_counter() - start
            rows = read_results(out)
        finally:
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    return {"wall_time": wall, "cluster_startup": startup, "points_per_minute": _rate(points, wall),
            "errors": sum(1 for row in rows if row["error"]), "cpu_share": _cpu_share(rows),
            "load_before": load_before}


class ExternalCluster:
    """``dask scheduler`` and ``dask worker --nworkers N`` on 127.0.0.1 (no dashboards), stopped on exit."""

    def __init__(self, workers, folder):
        self.workers, self.folder, self.processes = workers, Path(folder), []

    def __enter__(self):
        scheduler_file = self.folder / "scheduler.json"
        common = dict(cwd=self.folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        self.processes.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", str(scheduler_file)], **common))
        deadline = time.monotonic() + 60
        while not (scheduler_file.exists() and scheduler_file.read_text().strip()):
            if time.monotonic() > deadline or self.processes[0].poll() is not None:
                raise RuntimeError("the dask scheduler did not start")
            time.sleep(0.2)
        self.address = json.loads(scheduler_file.read_text())["address"]
        self.processes.append(subprocess.Popen(
            [sys.executable, "-m", "distributed.cli.dask_worker", self.address, "--nworkers", str(self.workers),
             "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard", "--memory-limit", "0",
             "--local-directory", str(self.folder / "workers")], **common))
        from distributed import Client

        with Client(self.address, timeout=60) as client:
            client.wait_for_workers(self.workers, timeout=120)
        return self

    def __exit__(self, *exc):
        for process in reversed(self.processes):
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGTERM)
        for process in self.processes:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
        return False


def point_breakdown(spec, count=4):
    """Mean seconds per stage of ``evaluate_point`` over ``count`` points, evaluated here (after one
    point that warms this process)."""
    _, points = sweep_points(TASK, spec)
    evaluate_point(points[0][2])
    totals, walls = {}, []
    for _, _, config_yaml in points[1:count + 1]:
        stages = Stages(enabled=False)
        start = time.perf_counter()
        evaluate_point(config_yaml, stages=stages)
        walls.append(time.perf_counter() - start)
        for name, label in STAGES.items():
            totals[name] = totals.get(name, 0.0) + sum(t for key, t in stages.times.items() if label in key)
    breakdown = {name: total / len(walls) for name, total in totals.items()}
    breakdown["point"] = sum(walls) / len(walls)
    # The simulated run alone: "simulation" includes its build, start and initialization.
    breakdown["simulated run"] = breakdown["simulation"] - breakdown["build"] - breakdown["start"] \
        - breakdown["initialize"]
    return breakdown


FRESH_WORKER = """
import json, sys, time
start = time.perf_counter()
from drake_hybrid.experiments.sweep import sweep_points
from drake_hybrid.experiments.sweep_point import evaluate_point
from drake_hybrid.experiments.sweep_spec import load_spec
imported = time.perf_counter() - start
_, points = sweep_points({task!r}, load_spec(text={spec!r}))
times = []
for _, _, config_yaml in points[:2]:
    start = time.perf_counter()
    evaluate_point(config_yaml)
    times.append(time.perf_counter() - start)
from drake_hybrid.control import fast_compile
print(json.dumps({{"import_s": imported, "first_point_s": times[0], "second_point_s": times[1],
                   "compile_job": fast_compile.job_running()}}))
"""


def fresh_worker(spec_text):
    """A new process's import and first two points, with numba's cache warm and empty (then the time
    until its background compile job has finished)."""
    script = FRESH_WORKER.format(task=TASK, spec=spec_text)
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        for label, environment in (("warm cache", dict(os.environ)),
                                   ("empty cache", dict(os.environ, NUMBA_CACHE_DIR=folder,
                                                        DRAKE_HYBRID_CACHE=folder))):
            start = time.perf_counter()
            out = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True,
                                 check=True).stdout
            entry = json.loads(out.strip().splitlines()[-1])
            entry["process_s"] = time.perf_counter() - start
            job = entry.pop("compile_job")
            if job:
                lock = Path(folder) / "fast_law" / "compiling.lock"
                while lock.exists() and time.perf_counter() - start < 600:
                    time.sleep(0.5)
                if lock.exists():                     # not done in 10 minutes: stop it, report it unfinished
                    os.killpg(job, signal.SIGTERM)
                entry["compile_job_done_after_s"] = time.perf_counter() - start
                entry["compiled"] = not lock.exists() and not (Path(folder) / "fast_law" / "failed").exists()
            results[label] = entry
    return results


def measure(duration=0.5, out=None, log=print):
    spec_text = SPEC.format(duration=duration)
    spec = load_spec(text=spec_text)
    points = len(spec.points())
    results = {"task": TASK, "points": points, "duration": duration, "cpu_count": os.cpu_count(), "runs": {}}
    for label, workers in (("serial", 0), ("1 worker", 1), ("2 workers", 2), ("4 workers", 4)):
        results["runs"][label] = run = timed_run(spec, points, workers=workers)
        log(f"  sweep {label:>9}: {points} points in {run['wall_time']:6.1f} s = {run['points_per_minute']:5.1f} "
            f"points/min (start-up {run['cluster_startup']:.1f} s, not counted); {run['errors']} errors; "
            f"CPU/wall {run['cpu_share']:.2f}; load before {run['load_before']:.1f}")
    with tempfile.TemporaryDirectory() as folder, ExternalCluster(2, folder) as cluster:
        results["runs"]["external scheduler, 2 workers"] = run = timed_run(spec, points, scheduler=cluster.address)
        log(f"  sweep on dask scheduler {cluster.address} (2 workers): {run['points_per_minute']:5.1f} points/min; "
            f"{run['errors']} errors; CPU/wall {run['cpu_share']:.2f}")
    serial = results["runs"]["serial"]["points_per_minute"]
    results["scaling"] = {label: run["points_per_minute"] / serial for label, run in results["runs"].items()}
    results["point_breakdown_s"] = point_breakdown(spec)
    log("  a point's seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in results["point_breakdown_s"].items()))
    results["fresh_worker"] = fresh_worker(spec_text)
    log(f"  fresh worker: {results['fresh_worker']}")
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "sweep_throughput.json").write_text(json.dumps(results, indent=2) + "\n")
        _plot(results, out / "sweep_throughput.png")
    return results


def _plot(results, path):
    from drake_hybrid.viz.figure_base import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.2))
    labels = list(results["runs"])
    ax.bar([label.replace("external scheduler, ", "external,\n") for label in labels],
           [results["runs"][label]["points_per_minute"] for label in labels], color="tab:blue")
    ax.set_ylabel("points per minute")
    ax.set_title(f"sweep throughput ({results['points']} points of {results['duration']:g} s, "
                 f"{results['cpu_count']} cores)", fontsize=9)
    ax.tick_params(axis="x", labelsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=0.5, help="simulated seconds per point")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args()
    measure(args.duration, args.out)
    print(f"wrote {Path(args.out) / 'sweep_throughput.json'}")


if __name__ == "__main__":
    main()
