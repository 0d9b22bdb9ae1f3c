"""The torque command a real arm is sent: the driver's gravity convention, limits, and the stops.

``DriverGravityCompensation``
    tau_out = tau_in + sign g(q), g(q) the torque that holds the arm against gravity. The Franka
    driver adds g(q) itself, so the controller's side sends the law's actuation minus g(q)
    (sign -1) and the simulated driver adds it back (sign +1).
``TorqueCommandSafety``
    what is published: nothing before the first valid status; the command clipped to the torque
    limits and rate-limited (|tau_k - tau_{k-1}| <= rate h); after a fault of the
    ``MessageWatchdog`` a latched stop, logged once with its reason:

    * STATUS_STALE: zero task torque (the driver's gravity compensation only), ramped at the rate
      limit: with no fresh joint state there is nothing safe to servo on;
    * FORCE_TORQUE_STALE: hold, a joint-space spring-damper K (q_stop - q) - D v about the
      joints at the stop (the status is still fresh); escalates to STATUS_STALE if the status
      goes stale too.
"""

import logging

import numpy as np

from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import Adder, Gain, MatrixGain

from drake_hybrid.control.sampling import declare_periodic_update, tick_offset
from drake_hybrid.core.linalg import all_finite
from drake_hybrid.hardware.messages import HardwareFault, Rejection
from drake_hybrid.hardware.watchdog import STATUS_FIELDS

LOGGER = logging.getLogger("drake_hybrid.hardware")
_STOPS = (HardwareFault.STATUS_STALE, HardwareFault.FORCE_TORQUE_STALE)


class DriverGravityCompensation(Diagram):
    """tau_out = tau_in + sign g(q).

    .. pydrake_system::

        name: DriverGravityCompensation
        input_ports:
        - torque
        - estimated_state
        output_ports:
        - torque

    g(q) = -CalcGravityGeneralizedForces (the torque that holds the arm still) of ``plant``, a
    plant of the arm and tool only (its state is the arm's [q; v]): the controller's plant on both
    sides (the simulated driver's own model of the arm, as the real driver has one).

    Made of Drake's own systems, so the tick pays no Python for it: the ``InverseDynamics``
    controller in its gravity-compensation mode (which outputs -CalcGravityGeneralizedForces at the
    positions of ``estimated_state``), mapped to actuation order and signed by a ``Gain`` (an identity
    actuation matrix) or a ``MatrixGain`` (sign B^-1), and an ``Adder``::

        estimated_state ──► InverseDynamics (gravity) ──► sign [B^-1] ──┐
        torque ────────────────────────────────────────────────────────Adder──► torque
    """

    def __init__(self, plant, sign):
        Diagram.__init__(self)
        if sign not in (-1, 1):
            raise ValueError(f"DriverGravityCompensation: sign must be -1 or +1, got {sign}")
        self._sign = float(sign)
        n = plant.num_actuated_dofs()
        actuation_from_torque = np.linalg.inv(plant.MakeActuationMatrix())
        builder = DiagramBuilder()
        gravity = builder.AddNamedSystem("gravity", InverseDynamics(
            plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation))
        # An identity actuation matrix (one actuator per joint, in joint order): sign g exactly.
        signed = builder.AddNamedSystem("signed_gravity", Gain(self._sign, n) if np.array_equal(
            actuation_from_torque, np.eye(n)) else MatrixGain(self._sign * actuation_from_torque))
        adder = builder.AddNamedSystem("sum", Adder(2, n))
        builder.Connect(gravity.get_output_port_generalized_force(), signed.get_input_port())
        builder.Connect(signed.get_output_port(), adder.get_input_port(1))
        builder.ExportInput(adder.get_input_port(0), "torque")
        builder.ExportInput(gravity.get_input_port_estimated_state(), "estimated_state")
        builder.ExportOutput(adder.get_output_port(), "torque")
        builder.BuildInto(self)
        self._signed = signed

    def gravity(self, context):
        """g(q) at the state on ``estimated_state`` (``context``: this system's), in actuation order."""
        return self._sign * self._signed.get_output_port().Eval(self.GetSubsystemContext(self._signed, context))


class TorqueCommandSafety(LeafSystem):
    """The command that is published, and the latched stops (see the module docstring).

    .. pydrake_system::

        name: TorqueCommandSafety
        input_ports:
        - torque
        - estimated_state
        - watchdog_status
        output_ports:
        - torque
        - enabled
        - stop

    ``torque`` (input) is the command the law asks for (already in the driver's gravity
    convention), ``watchdog_status`` the ``MessageWatchdog``'s. The ``torque`` output is the
    command decided at the last tick (state). The system ticks with the controller (at
    k h - SAMPLE_LEAD h) and reads the torque the law computes at that tick (the
    ``HybridController``'s ``computed_actuation``, which its update stores), so the command of a
    tick goes out in that tick, decided in the same event as the law's update. (Wired to a held
    actuation it would act on the torque of the tick before.) ``enabled`` is 0 until the first
    valid status (the runner publishes only while it is 1); ``stop`` is [fault, time of the stop]
    (fault 0: running; time NaN). ``initialize_command(context)`` decides the first command at the
    start (after the controller's initialization).

    Args:
        num_joints: n.
        period: the control period h (s).
        torque_limits: |tau_i| bound per joint (N m).
        torque_rate_limit: |d tau_i / dt| bound (N m / s), applied per tick as rate h.
        hold_stiffness, hold_damping: K, D of the hold after an F/T stop.
        initial_command: the command the first one is rate-limited against (default zeros: the
            driver's own gravity compensation).
    """

    def __init__(self, num_joints, period, torque_limits, torque_rate_limit, hold_stiffness, hold_damping,
                 initial_command=None):
        LeafSystem.__init__(self)
        self.num_joints = n = int(num_joints)
        self.period = float(period)
        self.torque_limits = np.asarray(torque_limits, dtype=float)
        if self.torque_limits.shape != (n,):
            raise ValueError(f"TorqueCommandSafety: torque_limits must have {n} entries, got {self.torque_limits.shape}")
        self.max_step = float(torque_rate_limit) * self.period
        self.hold_stiffness, self.hold_damping = float(hold_stiffness), float(hold_damping)
        self._initial_command = np.zeros(n) if initial_command is None else np.asarray(initial_command, dtype=float)
        self._torque_port = self.DeclareVectorInputPort("torque", n)
        self._state_port = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._status_port = self.DeclareVectorInputPort("watchdog_status", len(STATUS_FIELDS))
        # State: group 0 the command (n), output as it is (by Drake: no Python call in the publish);
        # group 1 the stop: [latched fault; stop time; ages and rejections at the stop (4); q at the stop (n)].
        self._layout = {"fault": 0, "time": 1, "details": slice(2, 6), "hold": slice(6, n + 6)}
        declare_periodic_update(self, self.period, tick_offset(self.period), self._update)
        self.DeclareStateOutputPort("torque", self.DeclareDiscreteState(n))
        self.DeclareDiscreteState(n + 6)
        self._enabled_port = self.DeclareVectorOutputPort("enabled", 1, self._calc_enabled)
        self.DeclareVectorOutputPort("stop", 2, self._calc_stop, prerequisites_of_calc={self.xd_ticket()})

    def get_enabled_output_port(self):
        return self._enabled_port

    def set_initial_command(self, context, command):
        """The command the first one is rate-limited against (e.g. what the driver holds at the start)."""
        context.SetDiscreteState(0, np.asarray(command, dtype=float))

    def initialize_command(self, context):
        """Decide the command at the start from the inputs there (call after Simulator.Initialize)."""
        command, stop, reason = self._decide(context)
        context.SetDiscreteState(0, command)
        context.SetDiscreteState(1, stop)
        if reason is not None:
            LOGGER.warning("%s", reason)

    def SetDefaultState(self, context, state):
        LeafSystem.SetDefaultState(self, context, state)
        stop = np.zeros(self.num_joints + 6)
        stop[self._layout["time"]] = np.nan
        state.get_mutable_discrete_state(0).SetFromVector(self._initial_command)
        state.get_mutable_discrete_state(1).SetFromVector(stop)

    def _decide(self, context):
        """(command, stop state after this tick, the reason of a stop that starts now or None)."""
        command = context.get_discrete_state(0).get_value()
        stop = context.get_discrete_state(1).get_value()
        status = self._status_port.Eval(context)
        layout = self._layout
        # HardwareFault values as ints (an IntEnum compares equal to its value; making one costs more).
        current, latched = int(status[0]), int(stop[layout["fault"]])
        reason = None
        escalate = latched == HardwareFault.FORCE_TORQUE_STALE and current == HardwareFault.STATUS_STALE
        if current in _STOPS and (latched == HardwareFault.NONE or escalate):
            stop = stop.copy()
            stop[layout["fault"]] = float(current)
            stop[layout["time"]] = context.get_time()
            stop[layout["details"]] = status[1:5]
            if not escalate:
                stop[layout["hold"]] = self._state_port.Eval(context)[:self.num_joints]
            latched = current
            reason = stop_reason(stop, layout)
        fault = latched if latched != HardwareFault.NONE else current
        if fault != HardwareFault.WAITING_FOR_STATUS:
            command = self._command(context, fault, command, stop)
        return command, stop, reason

    def _command(self, context, fault, previous, stop):
        n = self.num_joints
        if fault == HardwareFault.NONE:
            wanted = self._torque_port.Eval(context)
        elif fault == HardwareFault.STATUS_STALE:
            wanted = np.zeros(n)
        else:                                              # FORCE_TORQUE_STALE: hold the joints at the stop
            x = self._state_port.Eval(context)
            wanted = self.hold_stiffness * (stop[self._layout["hold"]] - x[:n]) - self.hold_damping * x[n:]
        if not all_finite(wanted):
            wanted = np.zeros(n)
        # np.clip, twice, written out (np.clip's dispatch costs more than the two comparisons).
        wanted = np.minimum(np.maximum(wanted, -self.torque_limits), self.torque_limits)
        return np.minimum(np.maximum(wanted, previous - self.max_step), previous + self.max_step)

    def _calc_enabled(self, context, output):
        waiting = int(self._status_port.Eval(context)[0]) == HardwareFault.WAITING_FOR_STATUS
        output.SetFromVector([0.0 if waiting else 1.0])

    def _calc_stop(self, context, output):
        stop = context.get_discrete_state(1).get_value()
        output.SetFromVector([stop[self._layout["fault"]], stop[self._layout["time"]]])

    def stop_reason(self, context):
        """The latched stop's reason as a sentence (None while running)."""
        stop = context.get_discrete_state(1).CopyToVector()
        if stop[self._layout["fault"]] == 0:
            return None
        return stop_reason(stop, self._layout)

    def _update(self, context, discrete_state):
        command, stop, reason = self._decide(context)
        if reason is not None:
            LOGGER.warning("%s", reason)
        discrete_state.get_mutable_vector(0).SetFromVector(command)
        discrete_state.get_mutable_vector(1).SetFromVector(stop)


def stop_reason(state, layout):
    """The sentence that says why and when the controller stopped (from TorqueCommandSafety's state)."""
    fault = HardwareFault(int(state[layout["fault"]]))
    status_age, force_torque_age, status_rejection, force_torque_rejection = state[layout["details"]]
    what = {HardwareFault.STATUS_STALE: f"robot status stale (newest valid one {status_age * 1e3:.1f} ms old); "
                                        "sending zero task torque",
            HardwareFault.FORCE_TORQUE_STALE: f"F/T reading stale (newest valid one {force_torque_age * 1e3:.1f} ms "
                                              "old); holding the joints"}[fault]
    rejected = [f"last rejected {kind} message: {Rejection(int(code)).name.lower().replace('_', ' ')}"
                for kind, code in (("status", status_rejection), ("F/T", force_torque_rejection)) if code]
    return f"stop at t = {state[layout['time']]:.4f} s: {what}" + (f" ({'; '.join(rejected)})" if rejected else "")
