"""The controller side's tick at a real arm's rate: the replayed Panda over ``memq://`` at 1 kHz.

    python benchmarks/realtime_tick.py [--task panda-table] [--seconds 10] [--compare] [--json FILE]
                                       [--no-results-md]

What ``drake-hybrid hardware timing --task panda-table --duration 10`` runs: a lock-step run records
what the simulated Panda sends; the recording is replayed at wall-clock rate to a fresh controller side
(``hardware.realtime.run_controller``, paced by ``ReplayPacer``), with the process's real-time settings
(``hardware.process_settings``: SCHED_FIFO, a core of its own, the idle states held off, the collector
paused, each where the process may). Figures: the controller's cost per tick (status in to command out)
p50 / p99 / max, the same by part (``hardware.tick.PARTS``), the deadline misses by cause, the wake-up
delay, the settings applied and the machine's load before and after. ``--compare`` also replays the same
recording with no real-time settings (``NO_SETTINGS``) and with the Simulator stepping the diagram
(``stepping="simulator"``, the same blocks, the same results), to show what each takes.

Targets (the issue of a real arm at 1 kHz): p50 <= 0.2 ms and p99 <= 0.5 ms on this machine, quiet.

Results: printed, written to ``results/realtime_tick.json`` (or ``--json``) and, unless
``--no-results-md``, into RESULTS.md's section "Real-time tick" (``benchmarks/run.py`` writes the same
section when it runs this part, ``realtime``). docs/hardware.md, "At the arm's rate", discusses them.
"""

import argparse
import json
import os
import re
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from pydrake.lcm import DrakeLcm

from drake_hybrid.hardware.controller_side import build_controller_station
from drake_hybrid.hardware.loop import run_hardware_loop, simulated_robot_hardware, start_state
from drake_hybrid.hardware.panda import panda_config, panda_drum_task, panda_table_task
from drake_hybrid.hardware.process_settings import NO_SETTINGS, RealTimeSettings
from drake_hybrid.hardware.realtime import ReplayPacer, run_controller, start_controller_state
from drake_hybrid.hardware.tick import PARTS

HERE = Path(__file__).resolve().parent
TASKS = {"panda-table": panda_table_task, "panda-drum": panda_drum_task}
TARGETS = {"p50_s": 2e-4, "p99_s": 5e-4}
SECTION = "## Real-time tick (`benchmarks/realtime_tick.py`)"
RUNS = {"real-time settings": (RealTimeSettings(), "direct"), "no real-time settings": (NO_SETTINGS, "direct"),
        "stepped by a Simulator": (RealTimeSettings(), "simulator")}


def replay(config, recorded, seconds, settings, stepping, url):
    """One replay of ``recorded`` to a fresh controller side: its TickTiming's summary."""
    lcm = DrakeLcm(url)
    start = start_state(config)
    station = build_controller_station(config, lcm, simulated_robot_hardware(config), initial_positions=start[1],
                                       with_loggers=False)
    timing = run_controller(station, lcm, seconds, pacer=ReplayPacer(lcm, recorded, config.control_period),
                            initial_state=start_controller_state(config, start), settings=settings, stepping=stepping)
    return timing.summary


def measure(task="panda-table", seconds=10.0, compare=False, log=print):
    """The figures of the module docstring: {"task", "seconds", "machine", "runs": {label: summary}, "targets"}."""
    config = panda_config(TASKS[task](), duration=seconds, speed=0.02)
    load_before = os.getloadavg()
    started = time.perf_counter()
    recorded = run_hardware_loop(config, None, duration=seconds, record=True).timing["recorded"]
    log(f"recorded {seconds:g} s of {task} in {time.perf_counter() - started:.0f} s "
        f"(load average {load_before[0]:.2f})")
    runs = {}
    for index, (label, (settings, stepping)) in enumerate(RUNS.items()):
        if index and not compare:
            break
        runs[label] = replay(config, recorded, seconds, settings, stepping, f"memq://realtime_tick_{index}")
        cost = runs[label]["controller_cost_s"]
        log(f"{label}: p50 {cost['p50'] * 1e3:.3f} ms, p99 {cost['p99'] * 1e3:.3f} ms, max {cost['max'] * 1e3:.2f} ms, "
            f"misses {runs[label]['deadline_misses']}")
    main = runs["real-time settings"]["controller_cost_s"]
    return {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "task": task, "seconds": seconds,
            "machine": {"cores": os.cpu_count(), "load_average_before": load_before,
                        "load_average_after": os.getloadavg()},
            "runs": runs,
            "targets": {"p50 <= 0.2 ms": {"value": main["p50"], "met": main["p50"] <= TARGETS["p50_s"]},
                        "p99 <= 0.5 ms": {"value": main["p99"], "met": main["p99"] <= TARGETS["p99_s"]}}}


def _ms(stats):
    return f"{stats['p50'] * 1e3:.3f} / {stats['p99'] * 1e3:.3f} / {stats['max'] * 1e3:.2f}"


def markdown_lines(result):
    """RESULTS.md's section of ``result`` (``measure``'s)."""
    machine = result["machine"]
    lines = [SECTION, "",
             f"{result['seconds']:g} s of `{result['task']}` at 1 kHz, the replayed Panda over memq:// "
             f"(`drake-hybrid hardware timing`), {result['date']}; load average "
             f"{machine['load_average_before'][0]:.2f} "
             f"before, {machine['load_average_after'][0]:.2f} after, on {machine['cores']} shared cores.", "",
             "| run | cost per tick ms (p50 / p99 / max) | deadline misses | late wake-up (after a long tick) | "
             "long tick (preempted) |", "|---|---:|---:|---:|---:|"]
    for label, run in result["runs"].items():
        lines.append(f"| {label} | {_ms(run['controller_cost_s'])} | {run['deadline_misses']} of "
                     f"{run['ticks_at_rate']} | {run['late_wake_up']} ({run['late_wake_up_after_a_long_tick']}) | "
                     f"{run['long_tick']} ({run['long_tick_preempted']}) |")
    main = result["runs"]["real-time settings"]
    timed, prepared = main.get("controller_cost_timed_by_part_s"), main.get("prepare_s")
    lines += ["", f"The tick by part, real-time settings, over the {main.get('ticks_timed_by_part', 0)} ticks timed by "
              f"part (one in {main.get('timed_every', 1)}; timing a tick by part adds to it: those ticks cost "
              f"{_ms(timed) if timed else '-'} ms) (us, p50 / p99 / max): " + "; ".join(
        f"{part} {main['tick_parts_s'][part]['p50'] * 1e6:.0f} / {main['tick_parts_s'][part]['p99'] * 1e6:.0f} / "
        f"{main['tick_parts_s'][part]['max'] * 1e6:.0f}" for part in PARTS) + ". Each tick prepared before its "
              f"status arrives (off the critical path, `ControllerTick.prepare`): {_ms(prepared) if prepared else '-'} "
              "ms.",
              "", "Settings applied: " + "; ".join(f"{key} {value}" for key, value in main["real_time"].items()
                                                   if key in ("scheduler", "cpu", "idle_states", "collector", "law"))
              + ".", "", "Targets: " + "; ".join(
                  f"{name}: {value['value'] * 1e3:.3f} ms, {'met' if value['met'] else 'not met'}"
                  for name, value in result["targets"].items()) + ".", ""]
    return lines


def write_results_md(result, path=HERE / "RESULTS.md"):
    """Replace (or add) RESULTS.md's section "Real-time tick" with ``result``'s."""
    text = path.read_text() if path.exists() else ""
    section = "\n".join(markdown_lines(result))
    pattern = re.compile(re.escape(SECTION) + r".*?(?=\n## |\Z)", re.DOTALL)
    if pattern.search(text):
        text = pattern.sub(lambda _: section.rstrip("\n"), text)
    else:
        text = text.rstrip("\n") + "\n\n" + section
    path.write_text(text.rstrip("\n") + "\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=sorted(TASKS), default="panda-table")
    parser.add_argument("--seconds", type=float, default=10.0, help="seconds at 1 kHz (default 10)")
    parser.add_argument("--compare", action="store_true",
                        help="also replay with no real-time settings and with the Simulator stepping the diagram")
    parser.add_argument("--json", type=Path, default=HERE / "results" / "realtime_tick.json")
    parser.add_argument("--no-results-md", action="store_true", help="do not write RESULTS.md's section")
    args = parser.parse_args(argv)
    result = measure(args.task, args.seconds, args.compare)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=1, default=float) + "\n")
    print("\n".join(markdown_lines(result)))
    if not args.no_results_md:
        write_results_md(result)
    return result


if __name__ == "__main__":
    main()
