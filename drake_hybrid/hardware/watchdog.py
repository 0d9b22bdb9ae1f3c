"""The controller side's view of the robot: the newest *valid* status and F/T reading, and how old
they are.

``MessageWatchdog`` reads the raw LCM messages (``lcmt_panda_status``, ``lcmt_force_torque``, as
Python objects from ``LcmSubscriberSystem``) and keeps, per context, the newest accepted one of each.
A message is accepted when it is new (a timestamp other than the newest accepted one), in order
(not older), of the arm's size and finite in every field; otherwise it is rejected (the reason is
kept) and the held values age. A message's age is measured on the controller's clock::

    age(t) = (t - arrival) + (latency - latency_0)       latency = arrival - timestamp

where ``arrival`` is the controller time at which the message was accepted and ``latency_0`` the
latency of the first accepted message (the two clocks' offset; in the lock-step loop both are the
simulation clock and latency_0 is the publish lead, a nanosecond). So a stream that stops, a
timestamp that stops advancing and a timestamp that falls behind all make the age grow.
"""

import math

import numpy as np

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from drake_hybrid.control.sampling import declare_periodic_update, tick_offset
from drake_hybrid.core.kinematics import declare_cached_value
from drake_hybrid.core.linalg import all_finite
from drake_hybrid.hardware.messages import HardwareFault, Rejection

# Record layout (one discrete state group per message kind).
SEEN, STAMP, ARRIVAL, LATENCY, OFFSET, REJECTION, VALUES = range(7)
# What the watchdog holds as of now: the two records, then each output's value.
_STATUS_RECORD, _FORCE_TORQUE_RECORD, _STATE, _TORQUE_EXTERNAL, _SENSOR_WRENCH, _STATUS = range(6)
# Layout of the ``watchdog_status`` output.
STATUS_FIELDS = ("fault", "status_age", "force_torque_age", "status_rejection", "force_torque_rejection")
# The faults as the floats the status output carries.
_NONE, _WAITING_FOR_STATUS, _STATUS_STALE, _FORCE_TORQUE_STALE = (float(fault) for fault in (
    HardwareFault.NONE, HardwareFault.WAITING_FOR_STATUS, HardwareFault.STATUS_STALE, HardwareFault.FORCE_TORQUE_STALE))


def status_fields(message, n):
    """(timestamp s, values [q; v; tau_ext], rejection) of an lcmt_panda_status; None if it is the
    empty message a subscriber holds before the first one arrives."""
    if message.num_joints == 0 and message.utime == 0:
        return None
    values = [*message.joint_position, *message.joint_velocity, *message.joint_torque_external]
    if message.num_joints != n or len(message.joint_position) != n or len(values) != 3 * n:
        return message.utime * 1e-6, None, Rejection.WRONG_SIZE
    if not all_finite(values):
        return message.utime * 1e-6, None, Rejection.NON_FINITE
    return message.utime * 1e-6, np.array(values, dtype=float), Rejection.NONE


def force_torque_fields(message):
    """(timestamp s, [tx, ty, tz, fx, fy, fz], rejection) of an lcmt_force_torque; None for the
    all-zero message a subscriber holds before the first one arrives."""
    values = [message.tx, message.ty, message.tz, message.fx, message.fy, message.fz]
    if message.timestamp == 0 and not any(values):
        return None
    if not all_finite(values):
        return message.timestamp * 1e-6, None, Rejection.NON_FINITE
    return message.timestamp * 1e-6, np.array(values, dtype=float), Rejection.NONE


def accept(record, fields, now):
    """The record after ``fields`` (status_fields / force_torque_fields) arrived at ``now``."""
    if fields is None:
        return record
    stamp, values, rejection = fields
    seen = record[SEEN] > 0
    if seen and stamp == record[STAMP]:
        return record                                   # the same message again: nothing new
    record = record.copy()
    if seen and stamp < record[STAMP]:
        rejection = Rejection.OUT_OF_ORDER
    if rejection != Rejection.NONE:
        record[REJECTION] = float(rejection)
        return record
    latency = now - stamp
    record[SEEN], record[STAMP], record[ARRIVAL], record[LATENCY] = 1.0, stamp, now, latency
    record[OFFSET] = record[OFFSET] if seen else latency
    record[VALUES:] = values
    return record


def age(record, now):
    """How old the record's newest accepted message is at ``now`` (inf if none was accepted)."""
    if record[SEEN] <= 0:
        return math.inf
    return (now - record[ARRIVAL]) + (record[LATENCY] - record[OFFSET])


class MessageWatchdog(LeafSystem):
    """The newest valid robot status and F/T reading, their ages, and the fault they imply.

    .. pydrake_system::

        name: MessageWatchdog
        input_ports:
        - lcmt_panda_status
        - lcmt_force_torque (with use_force_torque)
        output_ports:
        - estimated_state
        - torque_external
        - sensor_wrench
        - watchdog_status

    ``estimated_state`` is [q; v] of the newest accepted status (``initial_positions`` and zero
    velocity before the first), ``torque_external`` its external-torque estimate, ``sensor_wrench``
    the newest accepted F/T reading [t; f] (sensor frame, as sent). ``watchdog_status`` is
    [fault, status age, F/T age, status rejection, F/T rejection] (``STATUS_FIELDS``; fault a
    ``HardwareFault``, rejections ``Rejection`` codes of the last rejected message). The outputs
    take a message in the tick it arrives (they read the input ports); the periodic update at the
    control ticks stores it.

    Args:
        num_joints: n.
        period: the control period h (s); the watchdog ticks with the controller.
        max_status_age, max_force_torque_age: s; an older status is STATUS_STALE, an older F/T
            reading FORCE_TORQUE_STALE.
        use_force_torque: whether an F/T channel is read (else no ``lcmt_force_torque`` input).
        initial_positions: q before the first status (default zeros).
    """

    def __init__(self, num_joints, period, max_status_age, max_force_torque_age, use_force_torque=True,
                 initial_positions=None, status_type=None, force_torque_type=None):
        LeafSystem.__init__(self)
        self.num_joints = n = int(num_joints)
        self.period = float(period)
        self.max_status_age = float(max_status_age)
        self.max_force_torque_age = float(max_force_torque_age)
        self.use_force_torque = bool(use_force_torque)
        self._initial_state = np.concatenate([np.zeros(n) if initial_positions is None
                                              else np.asarray(initial_positions, dtype=float), np.zeros(n)])
        self._status_port = self.DeclareAbstractInputPort("lcmt_panda_status", AbstractValue.Make(status_type()))
        self._force_torque_port = None
        if self.use_force_torque:
            self._force_torque_port = self.DeclareAbstractInputPort("lcmt_force_torque",
                                                                    AbstractValue.Make(force_torque_type()))
        self.DeclareDiscreteState(VALUES + 3 * n)
        self.DeclareDiscreteState(VALUES + 6)
        declare_periodic_update(self, self.period, tick_offset(self.period), self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        # Everything as of now (state + what is on the inputs: the records and each output's value),
        # computed once per change of either (once a tick); the outputs copy their part of it.
        self._now = declare_cached_value(self, "as of now", self._as_of_now,
                                         {self.time_ticket(), self.xd_ticket(), self.all_input_ports_ticket()})
        now = {self._now.ticket()}
        for name, size, index in (("estimated_state", 2 * n, _STATE), ("torque_external", n, _TORQUE_EXTERNAL),
                                  ("sensor_wrench", 6, _SENSOR_WRENCH), ("watchdog_status", len(STATUS_FIELDS),
                                                                         _STATUS)):
            self.DeclareVectorOutputPort(name, size, self._copier(index), prerequisites_of_calc=now)

    def get_status_input_port(self):
        return self._status_port

    def get_force_torque_input_port(self):
        return self._force_torque_port

    # -- the records as of now (state + what is on the inputs) -----------------------------------
    def _parse(self, context):
        status = status_fields(self._status_port.Eval(context), self.num_joints)
        if self._force_torque_port is None:
            return status, None
        return status, force_torque_fields(self._force_torque_port.Eval(context))

    def _as_of_now(self, context):
        """(status record, F/T record, estimated_state, torque_external, sensor_wrench, watchdog_status)
        after the messages on the inputs arrived now."""
        status, force_torque = self._parse(context)
        now = context.get_time()
        # The held records read in place (accept copies one only to change it).
        status = accept(context.get_discrete_state(0).get_value(), status, now)
        force_torque = accept(context.get_discrete_state(1).get_value(), force_torque, now)
        n = self.num_joints
        seen = status[SEEN] > 0
        status_age, force_torque_age = age(status, now), age(force_torque, now)
        fault = _NONE
        if not seen:
            fault = _WAITING_FOR_STATUS
        elif status_age > self.max_status_age:
            fault = _STATUS_STALE
        elif self.use_force_torque and force_torque_age > self.max_force_torque_age:
            fault = _FORCE_TORQUE_STALE
        return (status, force_torque, status[VALUES:VALUES + 2 * n] if seen else self._initial_state,
                status[VALUES + 2 * n:], force_torque[VALUES:],
                [fault, status_age, force_torque_age if self.use_force_torque else 0.0, status[REJECTION],
                 force_torque[REJECTION]])

    def _copier(self, index):
        """An output's calc: its part (``index``) of the values as of now."""
        now = self._now

        def calc(context, output):
            output.SetFromVector(now.Eval(context)[index])

        return calc

    def status(self, context):
        """{name: value} of ``watchdog_status`` at ``context`` (fault as a HardwareFault)."""
        values = self.GetOutputPort("watchdog_status").Eval(context)
        status = dict(zip(STATUS_FIELDS, values))
        status["fault"] = HardwareFault(int(status["fault"]))
        return status

    def _update(self, context, discrete_state):
        status, force_torque = self._now.Eval(context)[:2]
        discrete_state.get_mutable_vector(0).SetFromVector(status)
        discrete_state.get_mutable_vector(1).SetFromVector(force_torque)
