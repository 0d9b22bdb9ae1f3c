"""What a real sensor's wrench needs before the controller: dropout (NaN) and stale-sample rejection
with a bounded hold, a tare against a constant bias, and the low-pass of ``systems.low_pass_filter``,
sampled at the control period. A TemplateSystem (float and AutoDiffXd), so closed loops linearize.
"""

import math
import sys

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.sampling import declare_periodic_update, tick_offset
from drake_hybrid.core.arguments import boolean, nonnegative, positive
from drake_hybrid.core.linalg import all_finite, value
from drake_hybrid.core.templates import default_instantiation
from drake_hybrid.systems.low_pass_filter import low_pass_coefficient


@TemplateSystem.define("WrenchConditioner_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def WrenchConditioner_(T):

    class Impl(LeafSystem_[T]):
        """Between a wrench sensor and the controller: rejects dropouts, tares, low-pass filters.

        .. pydrake_system::

            name: WrenchConditioner
            input_ports:
            - raw_wrench
            - sequence (only with use_sequence)
            - contact_phase (only with tare)
            output_ports:
            - wrench

        Every ``period`` (at the controller's tick) a raw sample u_k is *fresh* when it is finite
        and, with ``use_sequence``, its sequence number (the sensor's packet counter, as on an
        F/T sensor's streaming interface) differs from the last one: a stale sample, repeated
        by a stalled sensor, is not fresh. Then

            y_k = y_{k-1} + alpha (u_k - y_{k-1}),   alpha = 1 - exp(-2 pi f_c h)   (alpha = 1: no filter)

        and otherwise y_k = y_{k-1} (the last good value is held). The output is y_k - b (b: the
        tare) while the last fresh sample is at most ``max_hold_time`` old, and NaN after: the
        controller then ignores the wrench (no force feedback, integrals held) and the contact
        supervisor makes no decision, instead of acting on a value that no longer describes the
        contact. With ``tare``, b is the mean of the fresh samples taken while ``contact_phase``
        is TARE (the arm held still in free space): a constant sensor bias is removed.

        The output is direct feedthrough of the inputs (y_k from u_k at the same tick: no added
        delay); the state [y (6), b (6), tare samples, age (samples since the last fresh one),
        last sequence] advances at each tick.

        The AutoDiffXd instance computes on values (no derivatives through the conditioner).

        Args:
            period: the sampling period h (s), normally the control period.
            bandwidth_hz: f_c of the low-pass (0: none).
            max_hold_time: how long a dropout is bridged by holding (s, >= 0).
            use_sequence: declare the ``sequence`` input (stale-sample detection).
            tare: declare the ``contact_phase`` input and tare during TARE.
        """

        def _construct(self, period, bandwidth_hz=0.0, max_hold_time=0.01, use_sequence=False, tare=False,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            owner = "WrenchConditioner"
            self.period = positive(period, "period", owner, unit="s")
            self.bandwidth_hz = nonnegative(bandwidth_hz, "bandwidth_hz", owner, unit="Hz")
            self.max_hold_time = nonnegative(max_hold_time, "max_hold_time", owner, unit="s")
            self.use_sequence, self.tare = boolean(use_sequence, "use_sequence", owner), boolean(tare, "tare", owner)
            self._alpha = low_pass_coefficient(self.bandwidth_hz, self.period)
            self._max_age = int(math.floor(self.max_hold_time / self.period + 1e-9))
            self._raw_port = self.DeclareVectorInputPort("raw_wrench", 6)
            self._sequence_port = self.DeclareVectorInputPort("sequence", 1) if self.use_sequence else None
            self._phase_port = self.DeclareVectorInputPort("contact_phase", 1) if self.tare else None
            self.DeclareDiscreteState(15)
            declare_periodic_update(self, self.period, tick_offset(self.period), self._update)
            self.DeclareVectorOutputPort("wrench", 6, self._calc_wrench)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.period, other.bandwidth_hz, other.max_hold_time, other.use_sequence,
                            other.tare, converter=converter)

        def set_initial_output(self, context, y0, sequence=0.0):
            """Start from the reading y0 (no tare, fresh)."""
            state = np.zeros(15)
            state[:6] = value(np.asarray(y0))
            state[14] = float(sequence)
            context.get_mutable_discrete_state(0).SetFromVector(state)

        def _step(self, context):
            """(new state, output) of the tick at ``context``'s time (floats)."""
            state = value(context.get_discrete_state(0).CopyToVector())
            y, tare, samples, age, last_sequence = state[:6], state[6:12], state[12], state[13], state[14]
            raw = value(self._raw_port.Eval(context))
            fresh = all_finite(raw)
            sequence = last_sequence
            if self._sequence_port is not None:
                sequence = float(value(self._sequence_port.Eval(context))[0])
                fresh = fresh and sequence != last_sequence
            if fresh:
                y = y + self._alpha * (raw - y)
                age = 0.0
                if self._phase_port is not None and int(value(self._phase_port.Eval(context))[0]) == ContactPhase.TARE:
                    tare = (tare * samples + raw) / (samples + 1.0)
                    samples += 1.0
            else:
                age += 1.0
            output = y - tare if age <= self._max_age else np.full(6, np.nan)
            return np.concatenate([y, tare, [samples, age, sequence]]), output

        def _calc_wrench(self, context, output):
            output.SetFromVector(self._step(context)[1])

        def _update(self, context, discrete_state):
            discrete_state.get_mutable_vector(0).SetFromVector(self._step(context)[0])

    return Impl


WrenchConditioner = default_instantiation(WrenchConditioner_)
