"""What a real-time loop asks of the process and the operating system, applied for the loop's run
and undone after it.

``real_time(settings)`` is a context manager; inside it:

* the garbage collector is frozen and paused (``gc.freeze()``: the objects made so far are left out
  of every later collection; ``gc.disable()``: no collection starts in a tick). The tick still makes
  and frees small Python objects (floats, small arrays) from the interpreter's own pools, with no
  system call; with the collector paused, whatever a tick kept would pile up, so the runner reports
  the interpreter's allocated blocks kept per tick (``realtime.run_controller``);
* the loop's thread runs under the real-time scheduler (``SCHED_FIFO`` at ``priority``, as ros2_control's
  controller_manager does at 50, below libfranka's control thread at 99 if the driver runs on the same
  machine), so that no ordinary process preempts it;
* the thread is pinned to one core (``cpu``; -1: the last one it may use, the one usually isolated with
  ``isolcpus``), so the scheduler does not move it and its caches stay warm;
* the cores' deep idle states are held off (``idle_latency_us``: the power-management QoS request on
  ``/dev/cpu_dma_latency``, as cyclictest makes it; 0: a waiting core polls instead of halting), so a
  core that waits for the next status wakes at once and with its caches (on a virtual machine a halted
  core is given back to the host; docs/hardware.md has what it does to the tick).

Each is tried and reported: a setting the process may not make (no CAP_SYS_NICE, no rtprio limit,
a core outside its set) is refused politely: the report says what was refused and how a user allows
it, and the loop runs without it. The previous collector state, scheduler and affinity are restored
on exit, also after an error.
"""

import contextlib
import gc
import os
import struct
import sys
from dataclasses import dataclass
from typing import Dict, Iterator, Optional

from drake_hybrid.core.errors import ArgumentError

PRIORITY_ADVICE = ("the process may not use the real-time scheduler: give it CAP_SYS_NICE (e.g. `sudo setcap "
                   "cap_sys_nice+ep $(readlink -f $(which python3))`) or a real-time priority limit (`@realtime - "
                   "rtprio 99` in /etc/security/limits.conf, `ulimit -r 99`), or start it with `chrt -f 50`")


@dataclass
class RealTimeSettings:
    """``priority``: the SCHED_FIFO priority (1-99; None: leave the scheduler as it is); ``cpu``: the core
    to pin the loop's thread to (an index the process may use; -1: the last of them; None: leave the
    affinity); ``pause_collector``: freeze and pause the garbage collector during the run;
    ``idle_latency_us``: the longest wake-up from an idle state the cores may take (us, >= 0; None: leave
    the idle states as they are)."""

    priority: Optional[int] = 50
    cpu: Optional[int] = -1
    pause_collector: bool = True
    idle_latency_us: Optional[int] = 0

    def validate(self) -> "RealTimeSettings":
        if self.priority is not None and (isinstance(self.priority, bool) or not isinstance(self.priority, int)
                                          or not 1 <= self.priority <= 99):
            raise ArgumentError(f"RealTimeSettings.priority must be an integer in 1..99 or None, got {self.priority!r}")
        if self.cpu is not None and (isinstance(self.cpu, bool) or not isinstance(self.cpu, int) or self.cpu < -1):
            raise ArgumentError(f"RealTimeSettings.cpu must be a core index >= 0, -1 (the last one) or None, got "
                                f"{self.cpu!r}")
        if not isinstance(self.pause_collector, bool):
            raise ArgumentError(f"RealTimeSettings.pause_collector must be True or False, got {self.pause_collector!r}")
        if self.idle_latency_us is not None and (isinstance(self.idle_latency_us, bool)
                                                 or not isinstance(self.idle_latency_us, int)
                                                 or self.idle_latency_us < 0):
            raise ArgumentError(f"RealTimeSettings.idle_latency_us must be an integer >= 0 (us) or None, got "
                                f"{self.idle_latency_us!r}")
        return self


NO_SETTINGS = RealTimeSettings(priority=None, cpu=None, pause_collector=False, idle_latency_us=None)
IDLE_LATENCY_DEVICE = "/dev/cpu_dma_latency"


def _scheduler(settings: RealTimeSettings, report: Dict[str, object], undo: contextlib.ExitStack) -> None:
    if settings.priority is None:
        report["scheduler"] = "left as it is (no real-time priority asked for)"
        return
    if not hasattr(os, "sched_setscheduler"):
        report["scheduler"] = f"not available on {sys.platform}: running at normal priority"
        return
    policy, parameter = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(settings.priority))
    except PermissionError:
        report["scheduler"] = f"real-time priority refused: {PRIORITY_ADVICE}; running at normal priority"
        return
    except OSError as error:
        report["scheduler"] = f"real-time priority refused ({error.strerror}); running at normal priority"
        return
    undo.callback(os.sched_setscheduler, 0, policy, parameter)
    report["scheduler"] = f"SCHED_FIFO, priority {settings.priority}"


def _affinity(settings: RealTimeSettings, report: Dict[str, object], undo: contextlib.ExitStack) -> None:
    if settings.cpu is None:
        report["cpu"] = "not pinned (no core asked for)"
        return
    if not hasattr(os, "sched_setaffinity"):
        report["cpu"] = f"not pinned: not available on {sys.platform}"
        return
    allowed = sorted(os.sched_getaffinity(0))
    cpu = allowed[-1] if settings.cpu == -1 else settings.cpu
    if cpu not in allowed:
        report["cpu"] = f"not pinned: core {cpu} is not one this process may use ({allowed})"
        return
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError as error:
        report["cpu"] = f"not pinned: refused ({error.strerror})"
        return
    undo.callback(os.sched_setaffinity, 0, set(allowed))
    report["cpu"] = f"pinned to core {cpu} (of {allowed})"


def _idle_states(settings: RealTimeSettings, report: Dict[str, object], undo: contextlib.ExitStack) -> None:
    if settings.idle_latency_us is None:
        report["idle_states"] = "left as they are (no idle latency asked for)"
        return
    try:
        device = os.open(IDLE_LATENCY_DEVICE, os.O_WRONLY)
    except OSError as error:
        report["idle_states"] = (f"left as they are: {IDLE_LATENCY_DEVICE} refused ({error.strerror}; it needs root or "
                                 "write access to it)")
        return
    undo.callback(os.close, device)            # the request holds while the file is open
    os.write(device, struct.pack("i", settings.idle_latency_us))
    report["idle_states"] = (f"wake-up latency held to {settings.idle_latency_us} us ({IDLE_LATENCY_DEVICE})")


def _collector(settings: RealTimeSettings, report: Dict[str, object], undo: contextlib.ExitStack) -> None:
    if not settings.pause_collector:
        report["collector"] = "running (not paused)"
        return
    was_enabled, was_frozen = gc.isenabled(), gc.get_freeze_count() > 0
    gc.collect()
    gc.freeze()
    gc.disable()
    report["collector"] = f"frozen ({gc.get_freeze_count()} objects) and paused for the run"

    def restore() -> None:
        # A process frozen before (cli.main freezes its imports) keeps the run's objects frozen too: gc can
        # only unfreeze all of them, which would hand the caller's frozen objects back to the collector.
        if not was_frozen:
            gc.unfreeze()
        if was_enabled:
            gc.enable()

    undo.callback(restore)


@contextlib.contextmanager
def real_time(settings: Optional[RealTimeSettings] = None) -> Iterator[Dict[str, object]]:
    """Apply ``settings`` (default ``RealTimeSettings()``) for the ``with`` block; yields the report
    {"collector", "scheduler", "cpu", "idle_states": what was applied or refused, in words}. On exit, also
    after an error, the previous collector state, scheduler, affinity and idle states are restored."""
    settings = (RealTimeSettings() if settings is None else settings).validate()
    report: Dict[str, object] = {}
    with contextlib.ExitStack() as undo:
        _collector(settings, report, undo)
        _scheduler(settings, report, undo)
        _affinity(settings, report, undo)
        _idle_states(settings, report, undo)
        yield report
