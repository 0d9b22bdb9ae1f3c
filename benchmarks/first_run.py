"""The main job's first run: ``drake-hybrid simulate window-washing`` right after ``pip install .`` in a
fresh venv, then warm, and the command line's help.

    python benchmarks/first_run.py [--json FILE]

In a temporary folder: a new venv, ``pip install <this repository>`` (timed, not counted), then in
fresh processes, each timed from the command to its last line (wall clock):

* ``drake-hybrid --help`` and ``drake-hybrid simulate --help`` (median of five);
* the first ``drake-hybrid simulate window-washing``: nothing compiled yet (numba's cache is the new
  install's, drake_hybrid's its own empty folder), so the run uses the generic law while numba
  compiles the fast one in the background (control/fast_compile.py); then the time until that
  background job has finished;
* the same command warm (twice), and how much of it is not the simulated work: the wall time minus
  the "simulated in X s" the command prints (``Simulator.AdvanceTo``'s wall time).

Each run's stage lines (stderr) are kept, so the loading, building, start and writing times are in
the JSON too. Targets: the first run at most 30 s, warm at most 5 s beyond the simulated
work, both helps under 1 s, on 2 cores.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPOSITORY = HERE.parent
COMMAND = ["simulate", "window-washing", "--no-progress"]
STAGE = re.compile(r"^(.*) \.\.\. (\d+\.\d) s$", re.MULTILINE)
SIMULATED = re.compile(r"simulated in (\d+\.\d+) s")


def _run(arguments, environment, folder):
    start = time.perf_counter()
    done = subprocess.run(arguments, env=environment, cwd=folder, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, arguments))} failed: {done.stderr[-2000:]}")
    return wall, done


def _simulate(executable, environment, folder, out):
    wall, done = _run([executable, *COMMAND, "--out", str(out)], environment, folder)
    simulated = float(SIMULATED.search(done.stdout).group(1))
    return {"wall_s": wall, "simulated_work_s": simulated, "beyond_simulated_work_s": wall - simulated,
            "stages_s": {label: float(seconds) for label, seconds in STAGE.findall(done.stderr)},
            "generic_law": "this run used the generic law" in done.stdout}


def measure(log=print):
    results = {"load_average_at_start": os.getloadavg(), "cores": os.cpu_count()}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "venv", str(folder / "venv")], check=True)
        pip = folder / "venv" / "bin" / "pip"
        subprocess.run([str(pip), "install", "-q", str(REPOSITORY)], check=True, capture_output=True)
        results["install_s"] = time.perf_counter() - start
        executable = str(folder / "venv" / "bin" / "drake-hybrid")
        # As on a user's machine: this install's numba cache, drake_hybrid's own (empty) cache folder, the
        # default compile policy, bytecode written.
        environment = {key: value for key, value in os.environ.items()
                       if key not in ("NUMBA_CACHE_DIR", "DRAKE_HYBRID_COMPILE", "PYTHONDONTWRITEBYTECODE",
                                      "VIRTUAL_ENV", "PYTHONPATH")}
        environment["DRAKE_HYBRID_CACHE"] = str(folder / "cache")
        environment["PATH"] = f"{folder / 'venv' / 'bin'}{os.pathsep}{environment.get('PATH', '')}"
        for label, arguments in (("help", ["--help"]), ("simulate help", ["simulate", "--help"])):
            walls = [_run([executable, *arguments], environment, folder)[0] for _ in range(5)]
            results[f"{label}_s"] = statistics.median(walls)
            log(f"  drake-hybrid {' '.join(arguments)}: {results[f'{label}_s']:.2f} s (median of 5)")
        results["first_run"] = first = _simulate(executable, environment, folder, folder / "run1")
        log(f"  first run: {first['wall_s']:.1f} s (simulated work {first['simulated_work_s']:.1f} s, generic law: "
            f"{first['generic_law']}); stages {first['stages_s']}")
        lock = folder / "cache" / "fast_law" / "compiling.lock"
        while lock.exists() and time.perf_counter() - start < 1200:
            time.sleep(0.5)
        results["compile_job_done_s_after_install"] = time.perf_counter() - start - results["install_s"]
        results["compiled"] = not lock.exists() and not (folder / "cache" / "fast_law" / "failed").exists()
        log(f"  the background compile finished {results['compile_job_done_s_after_install']:.0f} s after the "
            f"install (compiled: {results['compiled']})")
        results["warm_runs"] = [_simulate(executable, environment, folder, folder / f"run{i}") for i in (2, 3)]
        for run in results["warm_runs"]:
            log(f"  warm run: {run['wall_s']:.1f} s, {run['beyond_simulated_work_s']:.1f} s beyond the simulated "
                f"work (generic law: {run['generic_law']}); stages {run['stages_s']}")
    results["load_average_at_end"] = os.getloadavg()
    return results


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, default=HERE / "results" / "first_run.json")
    args = parser.parse_args()
    results = measure()
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
