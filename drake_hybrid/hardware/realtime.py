"""The controller side at real-time rate, paced by the incoming status, timed per tick and by part.

``run_controller(station, lcm, duration, pacer=None)`` runs a ``ControllerStation`` the way it runs
next to a real driver: each tick waits for the next status message (the driver's 1 kHz clock paces
the loop), advances the controller's diagram by one period (``tick.ControllerTick``: the watchdog,
the law, the command's safety, without a Simulator) and publishes the command; inside
``process_settings.real_time`` (the collector paused, the real-time scheduler and a core of its own
when the process may). It returns a ``TickTiming`` whose ``summary`` holds:

* the controller's cost per tick: wall time from a status's arrival to its command's publication
  (each tick prepared before its status arrives, ``tick.ControllerTick.prepare``: ``prepare_s``),
  and the same by part (``tick.PARTS``) over the ticks timed by part: every ``timed_every``-th
  (``TIMED_EVERY``; timing a tick by part costs it some 20 us: the ports evaluated ahead of the
  updates, the clock readings), whose cost is also reported on its own;
* the period jitter: the spread of the intervals between status arrivals around h;
* the wake-up delay: how late a status was handled after it was due (with a pacer, which knows when
  it sent it; a real driver's send time is not on this machine's clock);
* deadline misses: ticks whose command went out more than h after their status was due, each put
  down to its cause: a *late wake-up* (the status waited, for the OS to wake the loop or for the
  previous tick to end) or a *long tick* (the tick itself ran long, preempted by the OS or by its own
  work: the thread's CPU time tells which); for each miss the cause is the part (wait or tick) that
  exceeded its median by more;
* what was applied at the start (scheduler, core, collector, the compiled law).

Tick 0 (the start: the initialization events, the compiled law loaded, or compiled if it is not on
disk yet) is reported on its own (``start_s``), not among the ticks at rate.

With a real driver (``--lcm-url udpm://...``) nothing else is needed. On ``memq://`` (tests, this
machine) ``ReplayPacer`` plays the driver: it publishes recorded status and F/T messages (from a
lock-step run, ``loop.run_hardware_loop(record=True)``) at their wall-clock instants, so the
controller sees the stream and the states a closed loop produced.
"""

import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, cast

import numpy as np

from pydrake.lcm import DrakeLcm, DrakeLcmInterface
from pydrake.systems.framework import Context, Diagram

from drake_hybrid.control import fast_compile
from drake_hybrid.control.controller import HybridController
from drake_hybrid.core.arguments import joint_vector
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array
from drake_hybrid.hardware.controller_side import ControllerStation, build_controller_station
from drake_hybrid.hardware.loop import HardwareRun, StartState, run_hardware_loop, simulated_robot_hardware, start_state
from drake_hybrid.hardware.messages import HardwareConfig
from drake_hybrid.hardware.process_settings import RealTimeSettings, real_time
from drake_hybrid.hardware.tick import PARTS, ControllerTick
from drake_hybrid.tasks.config import ScenarioConfig

WAKE_UPS = ("poll", "spin")
# The pacer sleeps until this long before a status is due, then spins: a sleep that overshoots by less
# than this (the kernel's timer slack is 50 us for an ordinary thread, 0 for a real-time one) is not late.
SPIN_MARGIN = 2e-4
# A tick in this many is timed by part (ControllerTick.timed_every); the others run without the timing.
TIMED_EVERY = 10


class ReplayPacer:
    """Publishes tick k's recorded messages when they are due: at once for tick 0 (the start), then at
    wall-clock time start + (k - 1) h, start being the first call for tick 1 (sleep until
    ``SPIN_MARGIN`` before, then spin). Returns the time the messages were due; ``sent`` keeps when
    they went out."""

    def __init__(self, lcm: DrakeLcmInterface, recorded: Sequence[Sequence[Tuple[str, bytes]]], period: float) -> None:
        self._lcm, self._recorded, self.period = lcm, recorded, float(period)
        self.start: Optional[float] = None
        self.sent: List[float] = []                 # wall time at which tick k's messages went out

    def __call__(self, k: int) -> float:
        now = time.perf_counter()
        if k == 0:
            due = now
        else:
            if self.start is None:
                self.start = now
            due = self.start + (k - 1) * self.period
            remaining = due - now
            if remaining > SPIN_MARGIN:
                time.sleep(remaining - SPIN_MARGIN)
            while time.perf_counter() < due:
                pass
        self.sent.append(time.perf_counter())
        for channel, data in self._recorded[k] if k < len(self._recorded) else []:
            self._lcm.Publish(channel, data)
        return due


@dataclass
class TickTiming:
    """The per-tick record of ``run_controller`` (wall-clock seconds of ``time.perf_counter``; index k =
    tick k, 0 the start) and its ``summary`` (the module docstring)."""

    period: float
    ticks: int
    due: Array                              # when each tick's status was due (the pacer's; else its arrival)
    arrivals: Array                         # when each tick's status was handled
    published: Array                        # when each tick's command went out (nan: not published)
    controller_cost: Array                  # s, status handled to command out (the tick)
    cpu: Array                              # s, the thread's CPU time in the tick
    parts: Array                            # s, (ticks + 1) x len(PARTS), the tick by part
    prepared: Optional[Array] = None        # s, each tick's prepare() before its status (nan: tick 0)
    missed_status: int = 0                  # ticks that ran without a new status (waited max_wait)
    stop: Optional[str] = None
    summary: Dict[str, Any] = field(default_factory=dict)


def statistics(values: Array) -> Optional[Dict[str, float]]:
    """{"p50", "p99", "max"} of the finite ``values`` (None if there are none)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return None
    return {"p50": float(np.percentile(values, 50)), "p99": float(np.percentile(values, 99)),
            "max": float(np.max(values))}


def miss_causes(period: float, due: Array, arrivals: Array, published: Array, cost: Array,
                cpu: Array) -> Dict[str, int]:
    """Deadline misses (command out more than ``period`` after its status was due) by cause (module
    docstring): {"deadline_misses", "late_wake_up", "late_wake_up_after_a_long_tick" (of those, the
    previous tick still running when the status was due), "long_tick", "long_tick_preempted" (of those,
    the thread had the CPU for less than half the tick)}. The arrays are of the ticks at rate."""
    wait = arrivals - due
    latency = published - due
    missed = ~(latency <= period)
    excess_wait = wait - np.nanmedian(wait)
    excess_tick = cost - np.nanmedian(cost)
    late = missed & (excess_wait >= excess_tick)
    long = missed & ~late
    previous_end = np.concatenate([[-np.inf], np.where(np.isfinite(published), published, arrivals + cost)[:-1]])
    return {"deadline_misses": int(np.sum(missed)), "late_wake_up": int(np.sum(late)),
            "late_wake_up_after_a_long_tick": int(np.sum(late & (previous_end > due))),
            "long_tick": int(np.sum(long)), "long_tick_preempted": int(np.sum(long & (cpu < 0.5 * cost)))}


def _law_report(station: ControllerStation) -> str:
    """Which law ran: the compiled one (loaded or compiled in how long) or the generic one (why)."""
    laws = station.controllers or [station.controller]
    fast = [law.fast_law for law in laws if isinstance(law, HybridController)]
    if fast and all(law is not None and law.compile_seconds is not None and law.fallbacks == 0 for law in fast):
        seconds = max(law.compile_seconds for law in fast if law is not None)
        return f"compiled (numba; loaded or compiled at the start in {seconds:.2f} s)"
    if fast and all(law is not None and law.compile_seconds is not None for law in fast):
        return "compiled, with evaluations handed to the generic law (fallbacks)"
    return "generic (numba unavailable, or the compiled law could not be built: see the warnings)"


def _wait_for_status(tick: ControllerTick, lcm: DrakeLcmInterface, seen: int, wait: float, wake_up: str) -> bool:
    """Handle messages until a status newer than ``seen`` has come (True) or ``wait`` s passed (False):
    blocking in the LCM's poll, which returns when a message arrives ("poll"), or handling without
    blocking in a busy loop ("spin": no wake-up by the kernel, a core kept busy)."""
    deadline = time.perf_counter() + wait
    timeout = 1 if wake_up == "poll" else 0
    while tick.statuses == seen and time.perf_counter() < deadline:
        lcm.HandleSubscriptions(timeout)
    return tick.statuses != seen


def run_controller(station: ControllerStation, lcm: DrakeLcmInterface, duration: float,
                   pacer: Optional[Callable[[int], float]] = None, max_wait: Optional[float] = None,
                   initial_state: Optional[Callable[[ControllerStation, Context], None]] = None,
                   first_wait: Optional[float] = None, wall_clock_stamps: bool = False,
                   settings: Optional[RealTimeSettings] = None, wake_up: str = "poll",
                   stepping: str = "direct", timed_every: int = TIMED_EVERY) -> TickTiming:
    """Run ``station`` paced by its status channel for ``duration`` s of ticks (module docstring).

    ``pacer(k)``, if given, is called before waiting for tick k's status (a memq stand-in for the
    driver) and returns the wall time that status was due. A tick whose status does not come within
    ``max_wait`` (default: the hardware config's max_status_age) runs anyway: the watchdog then
    decides (stale status: zero task torque). ``initial_state(station, context)`` may set the
    controller's states before initialization (the start's integrals and held torque).
    ``first_wait`` (s, default ``max_wait``) bounds the wait for the first status.
    ``wall_clock_stamps``: stamp commands with the wall clock (epoch us), as drake-franka-driver
    expects (it drops commands older than its --expire_sec). ``settings``: the real-time settings
    (``process_settings``; default ``RealTimeSettings()``, each refused politely when not permitted;
    ``NO_SETTINGS`` for none). ``wake_up``: "poll" or "spin" (``_wait_for_status``). ``stepping``,
    ``timed_every``: ControllerTick's ("direct", or "simulator" for the reference; a tick in
    ``timed_every`` timed by part, 1: every one)."""
    if wake_up not in WAKE_UPS:
        raise ArgumentError(f"run_controller: wake_up must be one of {', '.join(WAKE_UPS)}, got {wake_up!r}")
    period = float(station.config.control_period)
    max_wait = float(station.hardware.max_status_age if max_wait is None else max_wait)
    context = cast(Diagram, station.diagram).CreateDefaultContext()
    if initial_state is not None:
        initial_state(station, context)
    tick = ControllerTick(station, context, stepping, timed_every)
    ticks = int(round(duration / period))
    due, arrivals, published, cost, cpu, prepared = (np.full(ticks + 1, np.nan) for _ in range(6))
    parts = np.zeros((ticks + 1, len(PARTS)))
    missed, blocks = 0, sys.getallocatedblocks()
    clock, thread_clock = time.perf_counter, time.thread_time
    load_at_start = os.getloadavg()[0]
    with real_time(settings) as applied:
        for k in range(ticks + 1):
            seen = tick.statuses
            due[k] = pacer(k) if pacer is not None else np.nan
            got = _wait_for_status(tick, lcm, seen, max_wait if k > 0 or first_wait is None else float(first_wait),
                                   wake_up)
            arrivals[k] = start = clock()
            cpu_start = thread_clock()
            missed += not got
            while lcm.HandleSubscriptions(0) > 0:       # what else is queued (the F/T reading of the tick)
                pass
            received = clock() - start
            if k == 0:
                previous = fast_compile.set_policy("foreground")     # the compiled law now, not in a background job
                try:
                    tick.initialize()
                finally:
                    fast_compile.set_policy(previous)
            else:
                tick.advance(k)
            tick.time_receive(received)
            if tick.publish(utime=int(time.time() * 1e6) if wall_clock_stamps else None):
                published[k] = clock()
            cost[k] = clock() - start
            cpu[k] = thread_clock() - cpu_start
            parts[k] = tick.parts
            if k < ticks:                   # the next tick's preparation, off the critical path
                tick.prepare(k + 1)
                prepared[k + 1] = tick.prepare_seconds
            if k == 0:
                blocks = sys.getallocatedblocks()            # after the start (the law's load makes many)
    kept = (sys.getallocatedblocks() - blocks) / max(ticks, 1)
    tick.close()
    due = np.where(np.isnan(due), arrivals, due)
    stop_vector = cast(Array, station.safety.GetOutputPort("stop").Eval(station.safety.GetMyContextFromRoot(context)))
    timing = TickTiming(period=period, ticks=ticks, due=due, arrivals=arrivals, published=published,
                        controller_cost=cost, cpu=cpu, parts=parts, prepared=prepared, missed_status=missed,
                        stop=station.stop_reason(context) if stop_vector[0] > 0 else None)
    applied.update(allocated_blocks_kept_per_tick=kept, load_average=[load_at_start, os.getloadavg()[0]])
    timing.summary = summarize(timing, applied, paced=pacer is not None, law=_law_report(station), wake_up=wake_up,
                               stepping=stepping, timed_every=timed_every)
    return timing


def summarize(timing: TickTiming, applied: Dict[str, object], paced: bool, law: str, wake_up: str,
              stepping: str, timed_every: int = 1) -> Dict[str, Any]:
    """The figures of ``timing`` (module docstring), over the ticks at rate (1..N); tick 0 as ``start_s``;
    the parts over the ticks timed by part (their rows of ``timing.parts`` finite)."""
    period, rate = timing.period, slice(1, None)
    due, arrivals, published = timing.due[rate], timing.arrivals[rate], timing.published[rate]
    cost, cpu = timing.controller_cost[rate], timing.cpu[rate]
    causes = miss_causes(period, due, arrivals, published, cost, cpu)
    timed = np.all(np.isfinite(timing.parts[rate]), axis=1)
    return {
        "ticks": timing.ticks + 1, "ticks_at_rate": timing.ticks, "period_s": period, "rate_hz": 1.0 / period,
        "wall_s": float(timing.arrivals[-1] - timing.arrivals[0]),
        "start_s": float(timing.controller_cost[0]),
        "controller_cost_s": statistics(cost),
        "controller_cpu_s": statistics(cpu),
        "timed_every": timed_every, "ticks_timed_by_part": int(np.sum(timed)),
        "controller_cost_timed_by_part_s": statistics(cost[timed]),
        "prepare_s": statistics(timing.prepared[rate]) if timing.prepared is not None else None,
        "tick_parts_s": {part: statistics(timing.parts[rate, index]) for index, part in enumerate(PARTS)},
        "period_jitter_s": statistics(np.abs(np.diff(arrivals) - period)),
        "wake_up_delay_s": statistics(arrivals - due) if paced else None,
        "status_to_command_s": statistics(published - due),
        **causes,
        "ticks_without_new_status": timing.missed_status,
        "commands_published": int(np.sum(np.isfinite(timing.published))),
        "stop": timing.stop,
        "real_time": {**applied, "law": law, "wake_up": wake_up, "stepping": stepping,
                      "status_due": "when the pacer sent it" if paced else "its arrival (the driver's send time is "
                                    "not on this machine's clock)"},
    }


def start_controller_state(config: ScenarioConfig, start: StartState
                           ) -> Callable[[ControllerStation, Context], None]:
    """``initial_state`` for run_controller: the lock-step loop's start (loop.start_state) in the
    controller's states (integrals and held torque, the command limiter's reference, the filters)."""
    _, q0, held, reading, integrals = start

    def initial_state(station: ControllerStation, context: Context) -> None:
        law_context = station.controller.GetMyMutableContextFromRoot(context)
        law_context.SetDiscreteState(0, np.concatenate([integrals, held]))
        plant_context = station.controller_plant.CreateDefaultContext()
        q = joint_vector(q0, "start's q0", "start_controller_state", station.controller_plant)
        station.controller_plant.SetPositions(plant_context, q)
        gravity = np.negative(station.controller_plant.CalcGravityGeneralizedForces(plant_context))
        command = held - gravity if station.hardware.driver_compensates_gravity else held
        station.safety.set_initial_command(station.safety.GetMyMutableContextFromRoot(context), command)
        for part in (station.wrench_filter, station.conditioner):
            if part is not None:
                part.set_initial_output(part.GetMyMutableContextFromRoot(context), reading)

    return initial_state


def replay_timing(config: ScenarioConfig, hardware: Optional[HardwareConfig] = None, seconds: float = 10.0,
                  lcm_url: str = "memq://drake_hybrid_realtime", settings: Optional[RealTimeSettings] = None,
                  wake_up: str = "poll", stepping: str = "direct",
                  timed_every: int = TIMED_EVERY) -> Tuple[TickTiming, HardwareRun]:
    """A real-time run of ``seconds`` at the config's rate on ``memq://``: record what the robot
    sends in a lock-step run, then replay it at wall-clock rate to a fresh controller side paced by
    it (``settings``, ``wake_up``, ``stepping``, ``timed_every``: run_controller's). Returns (TickTiming, the lock-step
    HardwareRun)."""
    if not lcm_url.startswith("memq://"):
        raise ValueError(f"replay_timing replays in this process over memq:// only, got {lcm_url!r}")
    recorded_run = run_hardware_loop(config, hardware, duration=seconds, record=True)
    lcm = DrakeLcm(lcm_url)
    start = start_state(config)
    # The controller side the lock-step run had: its robot is the simulated plant.
    station = build_controller_station(config, lcm, simulated_robot_hardware(config, hardware),
                                       initial_positions=start[1], with_loggers=False)
    pacer = ReplayPacer(lcm, recorded_run.timing.pop("recorded"), station.config.control_period)
    timing = run_controller(station, lcm, seconds, pacer=pacer, initial_state=start_controller_state(config, start),
                            settings=settings, wake_up=wake_up, stepping=stepping, timed_every=timed_every)
    return timing, recorded_run
