"""The controller's side at real-time rate, paced by the incoming status, with per-tick timing.

``run_controller(station, lcm, duration, pacer=None)`` runs a ``ControllerStation`` the way it
runs next to a real driver: each tick waits for the next status message (the driver's 1 kHz
clock paces the loop), advances the controller's diagram by one period (watchdog, law, safety)
and publishes the command. It returns a ``TickTiming``:

* period jitter: the spread of the intervals between status arrivals around h (p50, p99, max of
  |interval - h|);
* the controller's cost: wall time from a status's arrival to its command's publication;
* deadline misses: ticks whose command went out more than h after their status was sent.

With a real driver (``--lcm-url udpm://...``) nothing else is needed. On ``memq://`` (tests, this
machine) ``ReplayPacer`` plays the driver: it publishes recorded status and F/T messages (from a
lock-step run, ``loop.run_hardware_loop(record=True)``) at their wall-clock instants k h, so the
controller sees the stream and the states a closed loop produced.
"""

import time
from dataclasses import dataclass, field
from typing import Dict

import numpy as np

from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator

from drake_hybrid.core.arguments import joint_vector
from drake_hybrid.control.sampling import SAMPLE_LEAD
from drake_hybrid.hardware.controller_side import build_controller_station
from drake_hybrid.hardware.loop import run_hardware_loop, start_state


class ReplayPacer:
    """Publishes tick k's recorded messages at wall-clock time start + k h (sleep, then spin)."""

    def __init__(self, lcm, recorded, period):
        self._lcm, self._recorded, self.period = lcm, recorded, float(period)
        self.start = None
        self.sent = []                      # wall time at which tick k's messages went out

    def __call__(self, k):
        if self.start is None:
            self.start = time.perf_counter()
        target = self.start + k * self.period
        remaining = target - time.perf_counter()
        if remaining > 3e-4:
            time.sleep(remaining - 2e-4)
        while time.perf_counter() < target:
            pass
        sent = time.perf_counter()
        for channel, data in self._recorded[k] if k < len(self._recorded) else []:
            self._lcm.Publish(channel, data)
        self.sent.append(sent)
        return sent


@dataclass
class TickTiming:
    period: float
    ticks: int
    arrivals: np.ndarray                    # wall time each tick's status was handled
    published: np.ndarray                   # wall time each tick's command went out (nan: not published)
    sent: np.ndarray                        # wall time each status was sent (the pacer's; else the arrival)
    controller_cost: np.ndarray             # s, the diagram's advance + publish per tick
    missed_status: int = 0                  # ticks that ran without a new status (waited max_wait)
    stop: object = None
    summary: Dict[str, object] = field(default_factory=dict)


def _stats(values):
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return None
    return {"p50": float(np.percentile(values, 50)), "p99": float(np.percentile(values, 99)),
            "max": float(np.max(values))}


def run_controller(station, lcm, duration, pacer=None, max_wait=None, initial_state=None, first_wait=None,
                   wall_clock_stamps=False):
    """Run ``station`` paced by its status channel for ``duration`` s of ticks (module docstring).

    ``pacer(k)``, if given, is called before waiting for tick k's status (a memq stand-in for the
    driver) and returns the wall time it sent it. A tick whose status does not come within
    ``max_wait`` (default: the hardware config's max_status_age) runs anyway: the watchdog then
    decides (stale status: zero task torque). ``initial_state(station, context)`` may set the
    controller's states before initialization (the start's integrals and held torque).
    ``first_wait`` (s, default ``max_wait``) bounds the wait for the first status.
    ``wall_clock_stamps``: stamp commands with the wall clock (epoch us), as drake-franka-driver
    expects (it drops commands older than its --expire_sec)."""
    period = float(station.config.control_period)
    max_wait = float(station.hardware.max_status_age if max_wait is None else max_wait)
    arrived = [0]
    subscription = lcm.Subscribe(station.hardware.status_channel, lambda data: arrived.__setitem__(0, arrived[0] + 1))
    context = station.diagram.CreateDefaultContext()
    if initial_state is not None:
        initial_state(station, context)
    simulator = Simulator(station.diagram, context)
    ticks = int(round(duration / period))
    arrivals, published, sent, cost = (np.full(ticks + 1, np.nan) for _ in range(4))
    missed = 0

    def wait_for_status(seen, wait):
        deadline = time.perf_counter() + wait
        while arrived[0] == seen and time.perf_counter() < deadline:
            lcm.HandleSubscriptions(1)
        # Deliver what else is queued (the F/T reading of the same tick) without waiting.
        while lcm.HandleSubscriptions(0) > 0:
            pass
        return arrived[0] != seen

    lead = SAMPLE_LEAD * period
    for k in range(ticks + 1):
        seen = arrived[0]
        sent[k] = pacer(k) if pacer is not None else np.nan
        got = wait_for_status(seen, max_wait if k > 0 or first_wait is None else float(first_wait))
        arrivals[k] = time.perf_counter()
        if not got:
            missed += 1
        if k == 0:
            simulator.Initialize()
            station.safety.initialize_command(station.safety.GetMyMutableContextFromRoot(context))
        else:
            station.before_tick(context, k)
            simulator.AdvanceTo(k * period + 0.5 * lead)
        if station.publish_command(context, utime=int(time.time() * 1e6) if wall_clock_stamps else None):
            published[k] = time.perf_counter()
        cost[k] = time.perf_counter() - arrivals[k]
    del subscription
    sent = np.where(np.isnan(sent), arrivals, sent)
    intervals = np.diff(arrivals)
    latency = published - sent
    stop_vector = station.safety.GetOutputPort("stop").Eval(station.safety.GetMyContextFromRoot(context))
    timing = TickTiming(period=period, ticks=ticks, arrivals=arrivals, published=published, sent=sent,
                        controller_cost=cost, missed_status=missed,
                        stop=station.stop_reason(context) if stop_vector[0] > 0 else None)
    timing.summary = {
        "ticks": ticks + 1, "period_s": period, "rate_hz": 1.0 / period,
        "wall_s": float(arrivals[-1] - arrivals[0]),
        "period_jitter_s": _stats(np.abs(intervals - period)),
        "controller_cost_s": _stats(cost),
        "status_to_command_s": _stats(latency),
        "deadline_misses": int(np.sum(~(latency <= period))),
        "ticks_without_new_status": missed,
        "commands_published": int(np.sum(np.isfinite(published))),
        "stop": timing.stop,
    }
    return timing


def start_controller_state(config, start):
    """``initial_state`` for run_controller: the lock-step loop's start (loop.start_state) in the
    controller's states (integrals and held torque, the command limiter's reference, the filters)."""
    _, q0, held, reading, integrals = start

    def initial_state(station, context):
        law_context = station.controller.GetMyMutableContextFromRoot(context)
        law_context.SetDiscreteState(0, np.concatenate([integrals, held]))
        plant_context = station.controller_plant.CreateDefaultContext()
        q = joint_vector(q0, "start's q0", "start_controller_state", station.controller_plant)
        station.controller_plant.SetPositions(plant_context, q)
        gravity = -station.controller_plant.CalcGravityGeneralizedForces(plant_context)
        command = held - gravity if station.hardware.driver_compensates_gravity else held
        station.safety.set_initial_command(station.safety.GetMyMutableContextFromRoot(context), command)
        for part in (station.wrench_filter, station.conditioner):
            if part is not None:
                part.set_initial_output(part.GetMyMutableContextFromRoot(context), reading)

    return initial_state


def replay_timing(config, hardware=None, seconds=10.0, lcm_url="memq://drake_hybrid_realtime"):
    """A real-time run of ``seconds`` at the config's rate on ``memq://``: record what the robot
    sends in a lock-step run, then replay it at wall-clock rate to a fresh controller side paced by
    it. Returns (TickTiming, the lock-step HardwareRun)."""
    if not lcm_url.startswith("memq://"):
        raise ValueError(f"replay_timing replays in this process over memq:// only, got {lcm_url!r}")
    recorded_run = run_hardware_loop(config, hardware, duration=seconds, record=True)
    lcm = DrakeLcm(lcm_url)
    start = start_state(config)
    station = build_controller_station(config, lcm, hardware, initial_positions=start[1], with_loggers=False)
    pacer = ReplayPacer(lcm, recorded_run.timing.pop("recorded"), station.config.control_period)
    timing = run_controller(station, lcm, seconds, pacer=pacer, initial_state=start_controller_state(config, start))
    return timing, recorded_run
