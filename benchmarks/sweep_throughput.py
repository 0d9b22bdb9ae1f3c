"""Sweep throughput (points per minute) on 1 and 2 Dask workers on this machine.

    python benchmarks/sweep_throughput.py [--points-per-axis N] [--duration S] [--out DIR]

The same sweep (window washing, pad modulus x K_fp x control period; each point
a simulation plus the continuous and the sampled-loop linearizations) runs
three times: serially in this process (no Dask), then on a LocalCluster of 1
and of 2 single-threaded worker processes. Each cluster is started and its
workers import drake_hybrid before the clock starts (the start-up is reported
separately), so the rate is the steady throughput. Prints points per minute,
the 2-worker / 1-worker ratio, and writes sweep_throughput.json and .png.
Each run also reports the CPU time over the wall time inside its points
(1.0 when each worker had a core to itself) and the load average before it:
on a shared 2-core machine the ratio falls short of 2 by that contention.
"""

import argparse
import json
import logging
import os
import tempfile
import time
from pathlib import Path

from drake_hybrid.experiments.sweep import read_results, run_sweep
from drake_hybrid.experiments.sweep_spec import parse_spec


def warm_up():
    import drake_hybrid.experiments.simulation  # noqa: F401
    import drake_hybrid.experiments.sweep  # noqa: F401

    return os.getpid()


def timed_sweep(spec, workers):
    """(seconds for the sweep, seconds to start the cluster, rows)."""
    with tempfile.TemporaryDirectory() as out:
        if workers == 0:
            start = time.perf_counter()
            run_sweep("window-washing", spec, out, workers=0, progress=False)
            return time.perf_counter() - start, 0.0, read_results(out)
        from distributed import Client, LocalCluster

        start = time.perf_counter()
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.ERROR)
        client = Client(cluster)
        client.run(warm_up)
        startup = time.perf_counter() - start
        try:
            start = time.perf_counter()
            run_sweep("window-washing", spec, out, scheduler=cluster.scheduler_address, progress=False)
            return time.perf_counter() - start, startup, read_results(out)
        finally:
            client.close()
            cluster.close()


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=0.5, help="simulated seconds per point")
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = parser.parse_args()
    spec = parse_spec({
        "base": {"duration": args.duration},
        "parameters": {"contact.pad_modulus": [5e6, 1e8], "gains.force_proportional": [0.25, 0.5, 0.75, 1.0],
                       "control_period": [0.001, 0.004]},
    })
    points = len(spec.points())
    results = {"points": points, "duration": args.duration, "cpu_count": os.cpu_count(), "runs": {}}
    for workers in (0, 1, 2):
        load_before = os.getloadavg()[0]
        wall, startup, rows = timed_sweep(spec, workers)
        rate = 60.0 * points / wall
        # CPU seconds per wall second inside the points: 1.0 when a worker had its core to itself.
        cpu_share = sum(row["cpu_time"] for row in rows) / sum(row["wall_time"] for row in rows)
        label = "serial (no Dask)" if workers == 0 else f"{workers} worker{'s' if workers > 1 else ''}"
        errors = sum(1 for row in rows if row["error"])
        results["runs"][str(workers)] = {"wall_time": wall, "cluster_startup": startup, "points_per_minute": rate,
                                         "errors": errors, "cpu_share": cpu_share, "load_before": load_before}
        print(f"{label:>18}: {points} points in {wall:6.1f} s = {rate:5.1f} points/min"
              f"{f' (cluster start-up {startup:.1f} s, not counted)' if workers else ''}; {errors} errors; "
              f"CPU/wall in the points {cpu_share:.2f}; load average before {load_before:.1f}")
    ratio = results["runs"]["2"]["points_per_minute"] / results["runs"]["1"]["points_per_minute"]
    results["ratio_2_to_1"] = ratio
    print(f"2 workers / 1 worker: {ratio:.2f}x (ideal 2 on {os.cpu_count()} cores; the machine is shared)")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep_throughput.json").write_text(json.dumps(results, indent=2))
    from drake_hybrid.viz.plotting import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5, 3.2))
    labels = ["serial", "1 worker", "2 workers"]
    ax.bar(labels, [results["runs"][k]["points_per_minute"] for k in ("0", "1", "2")], color="tab:blue")
    ax.set_ylabel("points per minute")
    ax.set_title(f"sweep throughput ({points} points, {args.duration:g} s each); 2/1 = {ratio:.2f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "sweep_throughput.png", dpi=120)
    print(f"wrote {out / 'sweep_throughput.json'}, {out / 'sweep_throughput.png'}")


if __name__ == "__main__":
    main()
