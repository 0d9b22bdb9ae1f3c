"""The ``drake-hybrid hardware`` command's summary in words: what ran and for how long, then for ``hil`` both
runs' errors after five design time constants and their difference (``hardware.loop.compare_with_direct``'s
figures), for ``timing`` and ``run`` the ticks, the controller's cost, the period jitter and the deadline
misses (``hardware.realtime``'s ``TickTiming.summary``); and whether the watchdog stopped the controller."""

from typing import Any, List, Mapping, Optional


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
        ticks, period = figures["ticks"], figures["period_s"]
        where = "replayed robot over " if mode == "timing" else "driver at "
        misses = figures["deadline_misses"]
        lines = [f"{head}: {ticks} ticks at {figures['rate_hz']:.0f} Hz over {figures['wall_s']:.2f} s of wall clock "
                 f"({where}{lcm_url}), in {figures['wall_time_s']:.1f} s",
                 f"  controller cost per tick (status in to command out): {milliseconds(figures['controller_cost_s'])}",
                 f"  period jitter |interval - {period * 1e3:g} ms|: {milliseconds(figures['period_jitter_s'])}",
                 f"  deadline misses (command more than {period * 1e3:g} ms after its status was sent): {misses} of "
                 f"{ticks} ticks ({100 * misses / ticks:.1f} %)",
                 f"  ticks without a new status: {figures['ticks_without_new_status']}; commands published: "
                 f"{figures['commands_published']} of {ticks}"]
    if figures["stop"] is None:
        lines.append("  no fault: the watchdog did not stop the controller")
    return lines


def hardware_fault_text(figures: Mapping[str, Any], task: str, mode: str) -> Optional[str]:
    """The fault's line when the watchdog stopped the controller (``figures["stop"]``: its reason), else None."""
    if figures["stop"] is None:
        return None
    return f"{task}, {mode}: fault: the watchdog stopped the controller, {figures['stop']}"
