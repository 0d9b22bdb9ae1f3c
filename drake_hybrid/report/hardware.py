"""The ``drake-hybrid hardware`` command's summary in words: what ran and for how long, then for ``hil`` both
runs' errors after five design time constants and their difference (``hardware.loop.compare_with_direct``'s
figures), for ``timing`` and ``run`` the real-time settings applied, the ticks, the controller's cost in all and by
part, the period jitter, the deadline misses by cause and what to do about each (``hardware.realtime``'s
``TickTiming.summary``); and whether the watchdog stopped the controller."""

from typing import Any, Dict, List, Mapping, Optional


def milliseconds(stats: Optional[Mapping[str, float]]) -> str:
    """Timing statistics ({"p50", "p99", "max"} in s, or None) in milliseconds."""
    if stats is None:
        return "none measured"
    return f"p50 {stats['p50'] * 1e3:.3g} ms, p99 {stats['p99'] * 1e3:.3g} ms, max {stats['max'] * 1e3:.3g} ms"


def hardware_lines(figures: Mapping[str, Any], task: str, mode: str, wrench_source: str,
                   lcm_url: Optional[str] = None) -> List[str]:
    """The lines ``drake-hybrid hardware MODE`` prints for its ``figures`` (with ``wall_time_s``, the command's
    own time): what ran, how long, the errors (hil) or the ticks and misses (timing, run: over ``lcm_url``), and
    "no fault" when the watchdog did not stop the controller (``hardware_fault_text`` says so otherwise)."""
    head = f"{task}, {mode} (wrench from {wrench_source})"
    if mode == "hil":
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
                     f"simulated time): {'none measured' if delay is None else milliseconds(delay)}"
                     + ("" if delay is None else " (LCM timestamps are whole microseconds: 1 us is their "
                        "resolution, not a delay)"))
    else:
        lines = [f"{head}: {figures['ticks']} ticks at {figures['rate_hz']:.0f} Hz over {figures['wall_s']:.2f} s of "
                 f"wall clock ({'replayed robot over ' if mode == 'timing' else 'driver at '}{lcm_url}), in "
                 f"{figures['wall_time_s']:.1f} s"] + timing_lines(figures)
    if figures["stop"] is None:
        lines.append("  no fault: the watchdog did not stop the controller")
    return lines


def hardware_fault_text(figures: Mapping[str, Any], task: str, mode: str) -> Optional[str]:
    """The fault's line when the watchdog stopped the controller (``figures["stop"]``: its reason), else None."""
    if figures["stop"] is None:
        return None
    return f"{task}, {mode}: fault: the watchdog stopped the controller, {figures['stop']}"


def microseconds(stats: Optional[Mapping[str, float]]) -> str:
    """Timing statistics ({"p50", "p99", "max"} in s, or None) as "p50 / p99 / max" in microseconds."""
    if stats is None:
        return "-"
    return f"{stats['p50'] * 1e6:.0f} / {stats['p99'] * 1e6:.0f} / {stats['max'] * 1e6:.0f}"


def timing_lines(figures: Mapping[str, Any]) -> List[str]:
    """The lines of a real-time run's figures (``hardware.realtime.summarize``): the settings applied, the start,
    the tick in all and by part, the jitter and wake-up delay, the deadline misses by cause, and the advice."""
    period, ticks = figures["period_s"], figures["ticks_at_rate"]
    settings: Dict[str, Any] = figures["real_time"]
    misses = figures["deadline_misses"]
    lines = [f"  real-time settings: scheduler {settings['scheduler']}; {settings['cpu']}; idle states "
             f"{settings['idle_states']}; collector {settings['collector']}; law {settings['law']}; wake-up by "
             f"{settings['wake_up']}",
             f"  start (tick 0: initialization, the compiled law loaded): {figures['start_s']:.2f} s; then "
             f"{ticks} ticks at rate",
             f"  controller cost per tick (status in to command out): {milliseconds(figures['controller_cost_s'])} "
             f"(the thread's CPU time: {milliseconds(figures['controller_cpu_s'])})",
             f"  by part, p50 / p99 / max in us ({by_part_ticks(figures)}): " + "; ".join(
                 f"{part} {microseconds(stats)}" for part, stats in figures["tick_parts_s"].items()),
             f"  period jitter |interval - {period * 1e3:g} ms|: {milliseconds(figures['period_jitter_s'])}"]
    if figures.get("prepare_s") is not None:
        lines.append(f"  each tick prepared before its status (off the critical path): "
                     f"{milliseconds(figures['prepare_s'])}")
    if figures["wake_up_delay_s"] is not None:
        lines.append(f"  wake-up delay (status due to handled): {milliseconds(figures['wake_up_delay_s'])}")
    lines += [f"  deadline misses (command more than {period * 1e3:g} ms after its status was due): {misses} of "
              f"{ticks} ticks ({100 * misses / max(ticks, 1):.2f} %): late wake-up {figures['late_wake_up']} "
              f"(after a long tick: {figures['late_wake_up_after_a_long_tick']}), long tick {figures['long_tick']} "
              f"(preempted: {figures['long_tick_preempted']})",
              f"  ticks without a new status: {figures['ticks_without_new_status']}; commands published: "
              f"{figures['commands_published']} of {figures['ticks']}"]
    lines += [f"  advice: {line}" for line in timing_advice(figures)]
    return lines


def by_part_ticks(figures: Mapping[str, Any]) -> str:
    """Which ticks the parts were timed in, and what those ticks cost (timing by part costs a tick some)."""
    every = figures.get("timed_every", 1)
    if every == 1:
        return "every tick"
    timed = figures.get("controller_cost_timed_by_part_s")
    cost = f", which cost {milliseconds(timed)}" if timed is not None else ""
    return f"one tick in {every}: {figures.get('ticks_timed_by_part', 0)} ticks{cost}"


def timing_advice(figures: Mapping[str, Any]) -> List[str]:
    """What to do about each cause of the deadline misses of a real-time run (``hardware.realtime.summarize``)."""
    settings: Dict[str, Any] = figures["real_time"]
    fifo = str(settings["scheduler"]).startswith("SCHED_FIFO")
    pinned = str(settings["cpu"]).startswith("pinned")
    idle = str(settings.get("idle_states", "")).startswith("wake-up latency held")
    load = settings.get("load_average") or [float("nan"), float("nan")]
    advice = []
    if figures["deadline_misses"] == 0:
        advice.append("no deadline missed")
    if figures["late_wake_up"]:
        woke_late = figures["late_wake_up"] - figures["late_wake_up_after_a_long_tick"]
        if woke_late:
            advice.append(f"{woke_late} late wake-ups: " + (
                "run at real-time priority (the scheduler was not set: see above)" if not fifo else
                "hold the cores' idle states off (/dev/cpu_dma_latency was not set: see above)" if not idle else
                "the loop woke late although at real-time priority: give it a core of its own (isolcpus= and "
                "irqaffinity= on the kernel's command line, nothing else pinned there), a PREEMPT_RT kernel, and "
                f"less load on the machine (load average {load[0]:.1f} at the start, {load[1]:.1f} at the end)"))
        if figures["late_wake_up_after_a_long_tick"]:
            advice.append(f"{figures['late_wake_up_after_a_long_tick']} late starts came after a long tick: the "
                          "previous tick still ran when the status was due (see the long ticks)")
    if figures["long_tick"]:
        preempted = figures["long_tick_preempted"]
        worked = figures["long_tick"] - preempted
        if preempted:
            advice.append(f"{preempted} long ticks were preempted (the thread had the CPU for less than half the "
                          "tick): " + ("run at real-time priority on a core of its own" if not (fifo and pinned)
                                       else "at real-time priority that is the kernel or the hypervisor: a core of "
                                            "its own (isolcpus, irqaffinity), a PREEMPT_RT kernel, no VM"))
        if worked:
            advice.append(f"{worked} long ticks were the tick's own work: check that the law is the compiled one "
                          f"(law: {settings['law']}), keep the CPU at full clock (the performance governor), and "
                          "see the tick by part for what takes the time")
    kept = settings.get("allocated_blocks_kept_per_tick")
    if kept is not None and kept > 10:
        advice.append(f"each tick kept {kept:.0f} Python objects while the collector was paused: memory grows "
                      "with the run's length")
    return advice
