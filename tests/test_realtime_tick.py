"""The controller side's tick at real-time rate: the direct stepping is the Simulator's, to the bit; the
tick is reported by part; deadline misses are put down to their cause; the process's real-time settings
are refused politely when not permitted and undone after a run. No timing is asserted (benchmarks/
realtime_tick.py measures it)."""

import gc
import os

import numpy as np
import pytest
from drake import lcmt_panda_command

from pydrake.lcm import DrakeLcm

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.hardware import process_settings
from drake_hybrid.hardware.controller_side import build_controller_station
from drake_hybrid.hardware.loop import run_hardware_loop, simulated_robot_hardware, start_state
from drake_hybrid.hardware.messages import HardwareConfig
from drake_hybrid.hardware.panda import panda_config, panda_drum_task
from drake_hybrid.hardware.process_settings import NO_SETTINGS, RealTimeSettings, real_time
from drake_hybrid.hardware.realtime import (TIMED_EVERY, ReplayPacer, miss_causes, replay_timing, run_controller,
                                            start_controller_state)
from drake_hybrid.hardware.tick import PARTS
from drake_hybrid.station.sensing import WristSensorConfig

pytest.importorskip("cmeel")      # example-robot-data (the Panda) is a test extra

PERIOD = 1e-3


@pytest.fixture(scope="module")
def drum():
    return panda_drum_task()


@pytest.mark.parametrize("variant", ["filter and gain change", "external torque, conditioned"])
def test_the_direct_tick_is_the_simulators_to_the_bit(drum, variant):
    """The lock-step loop with the controller side ticked directly and by a Simulator: every logged
    signal and every command on the wire the same, bit for bit. The variants hold every kind of event
    the controller side has: updates at k h - delta (watchdog, law, conditioner), at k h - delta / 2 (the
    command's safety), at k h (a filter: due at t = 0 before the first messages), a gain change at run
    time, and the loggers' publishes."""
    config = panda_config(drum, duration=0.06, wrist_sensor=variant.startswith("filter"))
    gain_changes = ()
    if variant.startswith("filter"):
        config.sensor = WristSensorConfig(bandwidth_hz=100.0)
        gain_changes = [(0.03, HybridGains(velocity=[24.0], position=[96.0], force_proportional=[1.0],
                                           force_integral=[30.0]))]
        hardware = HardwareConfig()
    else:
        config.sensor.condition, config.sensor.bandwidth_hz = True, 50.0
        hardware = HardwareConfig(wrench_source="external_torque")
    runs = [run_hardware_loop(config, hardware, gain_changes=gain_changes, stepping=stepping, timed_every=every)
            for stepping, every in (("direct", 1), ("simulator", 1), ("direct", 3))]
    direct, simulated, direct_untimed = (run.log for run in runs)
    assert runs[0].commands_published == runs[1].commands_published == runs[2].commands_published == 61
    assert set(direct) == set(simulated) == set(direct_untimed)
    for key in direct:
        assert np.array_equal(direct[key], simulated[key], equal_nan=True), key
        # Timing a tick by part (evaluating ports ahead of the updates) changes nothing computed.
        assert np.array_equal(direct[key], direct_untimed[key], equal_nan=True), key
    assert len(direct["wire_command"]) == 61


def test_a_replayed_controller_side_sends_the_lock_step_runs_commands_to_the_bit(drum):
    """The controller side at rate (run_controller: each tick prepared before its status arrives, one tick
    in TIMED_EVERY timed by part), fed what the simulated Panda sent in a lock-step run, sends that run's
    commands, bit for bit."""
    config = panda_config(drum, duration=0.03, speed=0.02)
    lock_step = run_hardware_loop(config, duration=0.03, record=True)
    lcm = DrakeLcm("memq://replayed_commands")
    start = start_state(config)
    station = build_controller_station(config, lcm, simulated_robot_hardware(config), initial_positions=start[1],
                                       with_loggers=False)
    sent = []
    subscription = lcm.Subscribe(station.hardware.command_channel,
                                 lambda data: sent.append(lcmt_panda_command.decode(data).joint_torque))
    timing = run_controller(station, lcm, 0.03, pacer=ReplayPacer(lcm, lock_step.timing["recorded"], 1e-3),
                            initial_state=start_controller_state(config, start), settings=NO_SETTINGS)
    while lcm.HandleSubscriptions(0) > 0:
        pass
    del subscription
    assert timing.missed_status == 0 and np.all(np.isfinite(timing.prepared[1:]))
    assert np.array_equal(np.array(sent), lock_step.log["wire_command"])


def assert_collector_restored(enabled, frozen):
    """The collector as it was before a run: enabled or not as before, and nothing frozen if nothing was.
    A process that had frozen objects already (``cli.main`` freezes its imports) keeps the ones frozen for
    the run too: Python cannot unfreeze a part of them (``process_settings``)."""
    assert gc.isenabled() == enabled
    if frozen == 0:
        assert gc.get_freeze_count() == 0
    else:
        assert gc.get_freeze_count() >= frozen


def test_a_real_time_run_reports_its_tick_by_part_and_restores_the_process(drum):
    """A short replayed run with the default real-time settings: the tick's parts are there for the start
    and every TIMED_EVERY-th tick (NaN in the others) and lie within it; the collector, the scheduler
    and the core are as they were afterwards."""
    config = panda_config(drum, duration=0.05, speed=0.02)
    enabled, frozen = gc.isenabled(), gc.get_freeze_count()
    scheduler, affinity = os.sched_getscheduler(0), os.sched_getaffinity(0)
    timing, _ = replay_timing(config, seconds=0.05)
    assert_collector_restored(enabled, frozen)
    assert os.sched_getscheduler(0) == scheduler and os.sched_getaffinity(0) == affinity
    summary = timing.summary
    assert summary["ticks"] == 51 and summary["commands_published"] == 51 and summary["stop"] is None
    assert set(summary["tick_parts_s"]) == set(PARTS)
    for stats in summary["tick_parts_s"].values():
        assert set(stats) == {"p50", "p99", "max"} and 0 <= stats["p50"] <= stats["p99"] <= stats["max"]
    timed = np.arange(51) % TIMED_EVERY == 0
    assert timing.parts.shape == (51, len(PARTS)) and np.all(np.isnan(timing.parts[~timed]))
    assert np.all(timing.parts[timed] >= 0)
    assert summary["ticks_timed_by_part"] == np.sum(timed[1:]) and summary["timed_every"] == TIMED_EVERY
    # The parts are timed inside the tick (status in to command out).
    assert np.all(timing.parts[timed].sum(axis=1) <= timing.controller_cost[timed])
    assert summary["deadline_misses"] == (summary["late_wake_up"] + summary["long_tick"])
    settings = summary["real_time"]
    assert set(settings) >= {"collector", "scheduler", "cpu", "idle_states", "law", "wake_up",
                             "allocated_blocks_kept_per_tick"}
    assert settings["law"].startswith("compiled")


def _timing(costs, waits, cpu=None):
    costs, waits = np.asarray(costs, dtype=float), np.asarray(waits, dtype=float)
    due = np.arange(costs.size) * PERIOD
    arrivals = due + waits
    return due, arrivals, arrivals + costs, costs, costs if cpu is None else np.asarray(cpu, dtype=float)


def test_deadline_misses_are_put_down_to_their_cause():
    """Four ticks late in four ways among ticks of 0.3 ms handled 20 us after their status was due: a
    late wake-up (the status waited 0.9 ms), a long tick that had the CPU (its own work), a long tick
    preempted (0.2 ms of CPU in 1.2 ms), and a tick that starts late because the one before it ran long."""
    costs, waits = [3e-4] * 12, [2e-5] * 12
    cpu = list(costs)
    waits[2] = 9e-4                           # woke late
    costs[5] = 1.1e-3                         # its own work ...
    cpu[5] = 1.1e-3
    costs[8], cpu[8] = 1.2e-3, 2e-4           # ... or preempted; the next one starts after it ended:
    waits[9] = 8e-4                           # its status was due at 9 ms, the tick before ended at 9.22 ms
    due, arrivals, published, cost, cpu_time = _timing(costs, waits, cpu)
    causes = miss_causes(PERIOD, due, arrivals, published, cost, cpu_time)
    assert causes == {"deadline_misses": 4, "late_wake_up": 2, "late_wake_up_after_a_long_tick": 1,
                      "long_tick": 2, "long_tick_preempted": 1}
    on_time = miss_causes(PERIOD, *_timing([3e-4] * 5, [2e-5] * 5))
    assert on_time["deadline_misses"] == on_time["late_wake_up"] == on_time["long_tick"] == 0


def test_real_time_settings_are_refused_politely_and_undone(monkeypatch):
    """Without permission for the real-time scheduler the report says so and how to get it, and the run
    goes on; a core the process may not use is not pinned; everything is undone on exit, also after an
    error in the block."""
    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(process_settings.os, "sched_setscheduler", refuse)
    monkeypatch.setattr(process_settings.os, "open", refuse)
    enabled, frozen, affinity = gc.isenabled(), gc.get_freeze_count(), os.sched_getaffinity(0)
    with real_time(RealTimeSettings(priority=50, cpu=max(affinity) + 1)) as report:
        assert "refused" in report["scheduler"] and "CAP_SYS_NICE" in report["scheduler"]
        assert report["scheduler"].endswith("running at normal priority")
        assert report["cpu"].startswith("not pinned: core") and os.sched_getaffinity(0) == affinity
        assert report["idle_states"].startswith("left as they are: /dev/cpu_dma_latency refused")
        assert report["collector"].startswith("frozen") and not gc.isenabled()
    assert_collector_restored(enabled, frozen)
    with pytest.raises(RuntimeError, match="inside"):
        with real_time(RealTimeSettings(priority=None, cpu=-1)) as report:
            assert report["scheduler"].startswith("left as it is")
            assert os.sched_getaffinity(0) == {max(affinity)}
            raise RuntimeError("inside")
    assert os.sched_getaffinity(0) == affinity and gc.isenabled() == enabled
    with real_time(NO_SETTINGS) as report:
        assert gc.isenabled() == enabled and report["collector"].startswith("running")


@pytest.mark.parametrize("settings, field", [(RealTimeSettings(priority=0), "priority"),
                                             (RealTimeSettings(priority=True), "priority"),
                                             (RealTimeSettings(cpu=-2), "cpu"),
                                             (RealTimeSettings(pause_collector=1), "pause_collector"),
                                             (RealTimeSettings(idle_latency_us=-1), "idle_latency_us")])
def test_real_time_settings_are_checked(settings, field):
    with pytest.raises(ArgumentError, match=f"RealTimeSettings.{field}"):
        with real_time(settings):
            pass
