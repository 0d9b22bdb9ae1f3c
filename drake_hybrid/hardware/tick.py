"""The controller side's tick: what ``Simulator.AdvanceTo`` does to the controller's diagram in one
control period, done directly, and timed by part.

``ControllerTick`` subscribes to the station's status and F/T channels, decodes each message once
and sets the newest on the diagram's message inputs (``controller_side``: fixed input values, read
without a copy). Between two statuses the controller's diagram has a fixed set of timed events: the
periodic discrete updates of its sampled systems (the watchdog, the law or laws, the command's safety,
a wrench filter or conditioner, a path source: at k h - SAMPLE_LEAD h, one event) and the loggers'
publishes. The tick runs them as a Simulator would, in its order and at its times (each
event's time computed as Drake computes it, offset + j period; at one time the publishes first, then
every discrete update computed from the same context and applied together; updates due when the
messages come, at the start, before the messages), so its results are the Simulator's to the last
bit (tests/test_realtime_tick.py), and it pays for nothing else: no search for the next event over
the diagram, no event dispatch for a system that keeps its update's handler
(``control.sampling.declare_periodic_update``: the handler is called on a copy of the state, as
Drake calls it), no copy of the state.

Before tick k's messages arrive, ``prepare(k)`` does what does not wait for them, off the critical
path (the runner calls it once the previous command is out): the gain change due, the context at the
tick's time, the desired values of a source that reads only the time. Then, once its status is in,
``advance(k)`` (a status in, its command out: the tick), timed by part (``PARTS``, seconds in
``parts``):

* receive: the messages handled since the status (the F/T reading), put into the subscribers' state;
* watchdog: the newest valid status and F/T reading, their ages, the watchdog's update;
* wrench: the measured wrench at the end-effector point (F/T conditioning or external torque, filter);
* source: the desired velocity, acceleration and force (a source that reads its inputs: the others
  are prepared);
* law: the hybrid law's discrete update (each gain set's);
* command: the driver's gravity convention, the limits and the stops (``TorqueCommandSafety``);
* publish: the command encoded and published (``publish``, timed there);
* framework: the rest (times set, updates applied, the loggers' publishes).

The parts are timed by evaluating, at the tick's time and in this order, the ports each part computes
before the updates that read them: Drake's caches then hand each value on, so the order changes
what is timed where, not what is computed.

``stepping="simulator"`` advances with a ``Simulator`` instead (the reference the direct stepping is
checked against; its parts but "receive" and "publish" are lumped in "framework"). The direct
stepping needs a diagram whose timed events are periodic discrete updates and the loggers' publishes
(every system ``controller_side`` composes); a system with continuous or abstract state is refused.
"""

import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple, Union, cast

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_status

from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import (Context, Diagram, DiscreteValues, FixedInputPortValue, InputPort, OutputPort,
                                       System)
from pydrake.systems.primitives import VectorLogSink

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.sampling import SAMPLE_LEAD
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.hardware.command import TorqueCommandSafety
from drake_hybrid.hardware.controller_side import FORCE_TORQUE_INPUT, STATUS_INPUT, ControllerStation
from drake_hybrid.hardware.gain_change import GainSelector
from drake_hybrid.hardware.watchdog import MessageWatchdog

PARTS = ("receive", "watchdog", "wrench", "source", "law", "command", "publish", "framework")
PART_DESCRIPTIONS = {
    "receive": "the messages after the status (F/T) handled and put into the diagram",
    "watchdog": "message validation, ages, the watchdog's update",
    "wrench": "the measured wrench at the end-effector point (F/T conditioning or external torque)",
    "source": "the desired velocity, acceleration and force",
    "law": "the hybrid law's update (the compiled law and its Drake calls)",
    "command": "the driver's gravity, torque limits, rate limit and stops",
    "publish": "the command encoded and published",
    "framework": "times set, updates applied, loggers",
}
STEPPINGS = ("direct", "simulator")
_RECEIVE, _WATCHDOG, _WRENCH, _SOURCE, _LAW, _COMMAND, _PUBLISH, _FRAMEWORK = range(len(PARTS))


def _no_clock() -> float:
    """The clock of a tick not timed by part (``ControllerTick.timed_every``)."""
    return 0.0


# A periodic discrete update: (system, its context, a buffer, part, the handler called directly or None).
_Update = Tuple[System, Context, DiscreteValues, int, Optional[Callable[[Context, DiscreteValues], None]]]


class _Timing:
    """One periodic timing (period, offset) and what happens at it: the discrete updates of ``updates``
    [(system, its context, a buffer, part)] or the publishes of ``loggers`` (never both: at one time the
    Simulator publishes before it updates); ``commands``: whether the command's safety is among the
    updates. ``index`` counts its samples: the next one is at offset + index period, as Drake computes it."""

    __slots__ = ("period", "offset", "updates", "loggers", "commands", "index", "next_time")

    def __init__(self, period: float, offset: float) -> None:
        self.period, self.offset = period, offset
        self.updates: List[_Update] = []
        self.loggers: List[Tuple[System, Context]] = []
        self.commands = False
        self.index, self.next_time = 0, offset

    def start(self, time_now: float) -> None:
        """The first sample at or after ``time_now`` (the Simulator's start catches events at t0)."""
        index = 0 if time_now <= self.offset else int(np.ceil((time_now - self.offset) / self.period))
        while self.offset + index * self.period < time_now:
            index += 1
        self.index, self.next_time = index, self.offset + index * self.period

    def step(self) -> None:
        self.index += 1
        self.next_time = self.offset + self.index * self.period


class ControllerTick:
    """The controller side of ``station`` ticked at ``context`` (its diagram's root context) without a
    Simulator (see the module docstring). It subscribes to the station's status and F/T channels on
    the station's LCM, decodes each message once and fixes the diagram's message inputs in
    ``context``; ``statuses`` counts the statuses received.

    ``initialize()`` is the start (tick 0: the messages so far, the initialization events, the
    command's first decision); ``advance(k)`` tick k (its event at k h - SAMPLE_LEAD h, the law's
    and the command's; stops at k h + SAMPLE_LEAD h / 2); ``publish(utime)`` sends the tick's command
    if enabled.
    ``parts`` holds the last tick's seconds by part (``PARTS``) if it was timed by part: every
    ``timed_every``-th tick (1: each), NaN in the others, which skip what the timing adds (the ports
    evaluated ahead of the updates, the clock readings)."""

    def __init__(self, station: ControllerStation, context: Context, stepping: str = "direct",
                 timed_every: int = 1) -> None:
        if stepping not in STEPPINGS:
            raise ArgumentError(f"ControllerTick: stepping must be one of {', '.join(STEPPINGS)}, got {stepping!r}")
        if not (isinstance(timed_every, int) and not isinstance(timed_every, bool) and timed_every >= 1):
            raise ArgumentError(f"ControllerTick: timed_every must be an integer >= 1, got {timed_every!r}")
        if station.diagram is None or station.lcm is None:
            raise ArgumentError("ControllerTick: the station must be built (build_controller_station)")
        self.station, self.context, self.stepping = station, context, stepping
        self.diagram: Diagram = station.diagram
        self.period = float(station.config.control_period)
        self.parts = np.zeros(len(PARTS))
        self.timed_every = timed_every
        self.statuses = 0
        self._clock: Callable[[], float] = time.perf_counter
        self._timed = True
        self._latest: Dict[str, object] = {}
        diagram, lcm, hardware = self.diagram, station.lcm, station.hardware
        # The message inputs, fixed to the empty messages the watchdog reads as "none yet".
        self._inputs: Dict[str, FixedInputPortValue] = {
            STATUS_INPUT: diagram.GetInputPort(STATUS_INPUT).FixValue(context, AbstractValue.Make(lcmt_panda_status()))}
        self._subscriptions = [lcm.Subscribe(hardware.status_channel, self._on_status)]
        if station.watchdog.use_force_torque:
            self._inputs[FORCE_TORQUE_INPUT] = diagram.GetInputPort(FORCE_TORQUE_INPUT).FixValue(
                context, AbstractValue.Make(lcmt_force_torque()))
            self._subscriptions.append(lcm.Subscribe(hardware.force_torque_channel, self._on_force_torque))
        self._simulator: Optional[Simulator] = Simulator(diagram, context) if stepping == "simulator" else None
        self._timings = self._collect_timings() if stepping == "direct" else []
        self._time = 0.0                            # the Simulator's time (the end of the last tick)
        self._context_time = context.get_time()     # the context's (the last event's, or prepare()'s)
        self._prepared = 0                          # the tick prepare() was done for
        self.prepare_seconds = 0.0
        self._enabled: Optional[bool] = None        # the tick's ``enabled``, when decided with the safety's update
        self._status_seen = False                   # ``enabled`` once true stays true (below)
        self._lead = SAMPLE_LEAD * self.period
        watchdog_context = station.watchdog.GetMyContextFromRoot(context)
        wrench_port = "sensor_wrench" if station.watchdog.use_force_torque else "torque_external"
        self._watchdog_ports = [(station.watchdog.GetOutputPort(name), watchdog_context)
                                for name in ("estimated_state", "watchdog_status", wrench_port)]
        self._watchdog_command_ports = self._watchdog_ports[:2]
        self._wrench_port = self._port_and_context(station.wrench_output)
        self._source_ports = ([self._port_and_context(station.source.GetOutputPort(name)) for name in
                               ("desired_velocity", "desired_acceleration", "desired_force")]
                              if station.source is not None else [])
        # What reads nothing but the time (and its own state): evaluated by prepare() at the tick's time.
        self._time_only_ports = (self._source_ports if station.source is not None and
                                 station.source.num_input_ports() == 0 else [])
        self._law_ports = [self._port_and_context(law.GetOutputPort("computed_actuation"))
                           for law in station.controllers or [station.controller]]
        safety_context = station.safety.GetMyContextFromRoot(context)
        self._command_inputs = [(station.safety.GetInputPort("torque"), safety_context)]

    # -- messages ---------------------------------------------------------------------------------
    def _on_status(self, data: bytes) -> None:
        self._latest[STATUS_INPUT] = lcmt_panda_status.decode(data)
        self.statuses += 1

    def _on_force_torque(self, data: bytes) -> None:
        self._latest[FORCE_TORQUE_INPUT] = lcmt_force_torque.decode(data)

    def _take_messages(self) -> None:
        """The newest messages onto the diagram's inputs (no copy: the watchdog reads these objects)."""
        for name, message in self._latest.items():
            self._inputs[name].GetMutableData().set_value(message)
        self._latest.clear()

    # -- the events -------------------------------------------------------------------------------
    def _port_and_context(self, port: OutputPort) -> Tuple[OutputPort, Context]:
        return port, cast(System, port.get_system()).GetMyContextFromRoot(self.context)

    def _part_of(self, system: System) -> int:
        station = self.station
        if isinstance(system, (HybridController, GainSelector)):
            return _LAW
        if isinstance(system, MessageWatchdog):
            return _WATCHDOG
        if isinstance(system, TorqueCommandSafety):
            return _COMMAND
        if system is station.source:
            return _SOURCE
        if system is station.wrench_filter or system is station.conditioner:
            return _WRENCH
        return _FRAMEWORK

    def _collect_timings(self) -> List[_Timing]:
        """The diagram's periodic timings with their discrete updates and loggers; ArgumentError for a
        system the direct stepping cannot run."""
        station, context = self.station, self.context
        loggers = {id(entry if isinstance(entry, System) else entry[0]): entry if isinstance(entry, System)
                   else entry[0] for entry in station.loggers.values()}
        timings: Dict[Tuple[str, float, float], _Timing] = {}

        def timing(kind: str, period: float, offset: float) -> _Timing:
            return timings.setdefault((kind, period, offset), _Timing(period, offset))

        for system in self.diagram.GetSystems():
            leaf_context = system.GetMyMutableContextFromRoot(context)
            if leaf_context.num_continuous_states() or leaf_context.num_abstract_states():
                raise ArgumentError(f"ControllerTick: system '{system.get_name()}' has continuous or abstract state; "
                                    "the direct stepping runs periodic discrete updates only: use "
                                    "stepping='simulator'")
            attribute = system.GetUniquePeriodicDiscreteUpdateAttribute()
            if attribute is not None:
                buffer, part = system.AllocateDiscreteVariables(), self._part_of(system)
                at = timing("update", attribute.period_sec(), attribute.offset_sec())
                at.updates.append((system, leaf_context, buffer, part, getattr(system, "periodic_update_handler", None)))
                at.commands = at.commands or part == _COMMAND
            elif leaf_context.num_discrete_state_groups():
                raise ArgumentError(f"ControllerTick: system '{system.get_name()}' has discrete state without one "
                                    "periodic update; use stepping='simulator'")
        log_period = float(station.config.log_period)
        for sink in loggers.values():
            assert isinstance(sink, VectorLogSink)
            timing("publish", log_period, 0.0).loggers.append((sink, sink.GetMyContextFromRoot(context)))
        return list(timings.values())

    def _warm(self, ports: Sequence[Tuple[Union[InputPort, OutputPort], Context]], part: int) -> None:
        start = self._clock()
        for port, port_context in ports:
            port.Eval(port_context)
        self.parts[part] += self._clock() - start

    def _run_events_until(self, end: float) -> None:
        """Every timed event up to ``end`` (inclusive for publishes, as the Simulator's step to ``end``)."""
        context, clock, parts, timings = self.context, self._clock, self.parts, self._timings
        while True:
            now = min([timing.next_time for timing in timings]) if timings else np.inf
            if now > end:
                break
            due = [timing for timing in timings if timing.next_time == now]
            start = clock()
            if now != self._context_time:          # prepare() may have set it already
                context.SetTime(now)
                self._context_time = now
            for timing in due:
                for sink, sink_context in timing.loggers:
                    sink.ForcedPublish(sink_context)
            updates = due[0].updates if len(due) == 1 else [update for timing in due for update in timing.updates]
            parts[_FRAMEWORK] += clock() - start
            if updates:
                if self._timed:
                    self._warm_parts(updates)
                for system, leaf_context, buffer, part, handler in updates:
                    start = clock()
                    if handler is None:
                        buffer.SetFrom(system.EvalUniquePeriodicDiscreteUpdate(leaf_context))
                    else:                        # what that calls, without Drake's event dispatch
                        buffer.SetFrom(leaf_context.get_discrete_state())
                        handler(leaf_context, buffer)
                    parts[part] += clock() - start
                start = clock()
                for _, leaf_context, buffer, _, _ in updates:
                    leaf_context.get_mutable_discrete_state().SetFrom(buffer)
                parts[_FRAMEWORK] += clock() - start
                if any([timing.commands for timing in due]):
                    # Whether the command may go out, decided now: the watchdog's status at this time is
                    # already computed, and until the publish nothing but the time (not a status's being
                    # seen, which is all ``enabled`` reads) changes. A status once seen stays seen (the
                    # watchdog's records never forget one), so once enabled it is not asked again.
                    start = clock()
                    self._status_seen = self._status_seen or self.station.enabled(context)
                    self._enabled = self._status_seen
                    parts[_PUBLISH] += clock() - start
            for timing in due:
                timing.step()
        # The Simulator's time is now ``end``; the context's stays at the last event's until prepare()
        # (nothing computed between two ticks reads the time, and a gain change is made at ``end``).
        self._time = end

    def _warm_parts(self, updates: List[_Update]) -> None:
        """Evaluate, in the parts' order, what the updates at this time read (module docstring)."""
        parts_due = {update[3] for update in updates}
        if _LAW in parts_due:
            self._warm(self._watchdog_ports, _WATCHDOG)
            self._warm([self._wrench_port], _WRENCH)
            self._warm(self._source_ports, _SOURCE)
            self._warm(self._law_ports, _LAW)
        elif _COMMAND in parts_due:
            self._warm(self._watchdog_command_ports, _WATCHDOG)
        if _COMMAND in parts_due:
            self._warm(self._command_inputs, _COMMAND)

    # -- the tick ---------------------------------------------------------------------------------
    def initialize(self) -> None:
        """Tick 0: the messages so far into the diagram, the initialization events (the watchdog takes
        the status, the law its first actuation and start check), the command's first decision."""
        self._time_parts(True)
        start = self._clock()
        self._take_messages()
        self.parts[_RECEIVE] += self._clock() - start
        start = self._clock()
        if self._simulator is not None:
            self._simulator.Initialize()
            self._time = self.context.get_time()
        else:
            time_now = self.context.get_time()
            self.diagram.ExecuteInitializationEvents(self.context)
            for timing in self._timings:
                timing.start(time_now)
                if timing.next_time == time_now and timing.loggers:      # the Simulator publishes at t0 here
                    for sink, sink_context in timing.loggers:
                        sink.ForcedPublish(sink_context)
                    timing.step()
            self._time = self._context_time = time_now
        safety = self.station.safety
        safety.initialize_command(safety.GetMyMutableContextFromRoot(self.context))
        self.parts[_FRAMEWORK] += self._clock() - start

    def prepare(self, k: int) -> None:
        """What tick ``k`` >= 1 does before its messages, done before they arrive: the runner calls it
        after the previous command went out, off the critical path (``advance(k)`` calls it if not;
        ``prepare_seconds`` is its wall time). As the Simulator would, before the new messages are in:
        the gain change due at k (``before_tick``, at the previous tick's end time), the updates due
        then (at the start: offset-0 updates at t0); then the context at tick k's first event time and
        what reads nothing but the time evaluated there (a source without inputs: the desired values)."""
        start = time.perf_counter()
        context = self.context
        if self._simulator is not None:
            self.station.before_tick(context, k)
            self._simulator.AdvanceTo(self._time)
        else:
            if self.station.changes_gains_at(k) and self._context_time != self._time:
                context.SetTime(self._time)
                self._context_time = self._time
            self.station.before_tick(context, k)
            if any(timing.next_time <= self._time for timing in self._timings):
                self._run_events_until(self._time)
            first = min([timing.next_time for timing in self._timings]) if self._timings else np.inf
            if first <= self._end(k):
                if first != self._context_time:
                    context.SetTime(first)
                    self._context_time = first
                for port, port_context in self._time_only_ports:
                    port.Eval(port_context)
        self._prepared = k
        self.prepare_seconds = time.perf_counter() - start

    def _end(self, k: int) -> float:
        return k * self.period + 0.5 * self._lead

    def advance(self, k: int) -> None:
        """Tick ``k`` >= 1: ``prepare(k)`` unless done, the newest messages, every event up to
        k h + SAMPLE_LEAD h / 2; timed by part if k is a multiple of ``timed_every`` (else ``parts`` is
        NaN)."""
        if self._prepared != k:
            self.prepare(k)
        self._time_parts(k % self.timed_every == 0)
        start = self._clock()
        self._take_messages()
        self.parts[_RECEIVE] += self._clock() - start
        end = self._end(k)
        if self._simulator is not None:
            start = self._clock()
            self._simulator.AdvanceTo(end)
            self._time = end
            self.parts[_FRAMEWORK] += self._clock() - start
        else:
            self._run_events_until(end)

    def _time_parts(self, timed: bool) -> None:
        """Time this tick by part (``parts`` zeroed, filled as it runs) or not (``parts`` NaN; every
        clock reading in the tick is then 0)."""
        self._timed = timed
        self._clock = time.perf_counter if timed else _no_clock
        self.parts[:] = 0.0 if timed else np.nan

    def publish(self, utime: Optional[int] = None) -> bool:
        """Publish the tick's command if the safety enables it (``ControllerStation.publish_command``)."""
        start = self._clock()
        published = self.station.publish_command(self.context, utime, self._enabled)
        self._enabled = None
        self.parts[_PUBLISH] += self._clock() - start
        return published

    def time_receive(self, seconds: float) -> None:
        """Add ``seconds`` of message handling done by the runner (draining the LCM after the status)."""
        if self._timed:
            self.parts[_RECEIVE] += seconds

    def close(self) -> None:
        """Drop the LCM subscriptions."""
        self._subscriptions.clear()
