"""A first-order low-pass with a bandwidth in Hz, continuous or sampled exactly, and its coefficient
and lag.

On a continuous plant, the contact results are direct feedthrough of the actuation, so plant ->
sensor -> controller -> plant is an algebraic loop; a filter breaks it (see docs/drake_notes.md).
A TemplateSystem (float and AutoDiffXd), so closed loops linearize.
"""

import math
import sys

from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.sampling import declare_periodic_update
from drake_hybrid.core.arguments import number, positive
from drake_hybrid.core.templates import default_instantiation

MAX_FILTER_SIZE = 10_000      # entries a LowPassFilter filters (a wrench has 6)


def low_pass_coefficient(bandwidth_hz, period):
    """alpha = 1 - exp(-2 pi f_c h): the exact discretization of y-dot = 2 pi f_c (u - y) for a held
    input (1 when bandwidth_hz is 0: no filtering)."""
    if not bandwidth_hz > 0:
        return 1.0
    return 1.0 - math.exp(-2 * math.pi * bandwidth_hz * period)


def low_pass_lag(bandwidth_hz, period):
    """T (s): how far a first-order low-pass's output trails a ramp input, 1 / (2 pi f_c)
    continuous (``period`` None or 0), h (1 - alpha) / alpha sampled (``low_pass_coefficient``);
    0 without a filter (bandwidth_hz 0)."""
    if not bandwidth_hz > 0:
        return 0.0
    if not period:
        return 1.0 / (2 * math.pi * bandwidth_hz)
    alpha = low_pass_coefficient(bandwidth_hz, period)
    return period * (1.0 - alpha) / alpha


@TemplateSystem.define("LowPassFilter_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def LowPassFilter_(T):

    class Impl(LeafSystem_[T]):
        """First-order low-pass y-dot = 2 pi f_c (u - y), continuous or sampled exactly.

        .. pydrake_system::

            name: LowPassFilter
            input_ports:
            - u
            output_ports:
            - y

        The output is the state (no direct feedthrough). With ``period`` h the
        update is y+ = y + (1 - exp(-2 pi f_c h)) (u - y), the exact
        discretization for a held input. Set the initial state with
        ``set_initial_output``.
        """

        def _construct(self, size, bandwidth_hz, period=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            size = number(size, "size", "LowPassFilter", low=1, high=MAX_FILTER_SIZE, integer=True)
            bandwidth_hz = positive(bandwidth_hz, "bandwidth_hz", "LowPassFilter", unit="Hz")
            period = positive(period, "period", "LowPassFilter", unit="s", allow_none=True)
            self._size, self.bandwidth_hz, self.period = size, bandwidth_hz, period
            self._rate = 2 * math.pi * self.bandwidth_hz
            self.DeclareVectorInputPort("u", size)
            if period is None:
                state = self.DeclareContinuousState(size)
                self.DeclareStateOutputPort("y", state)
            else:
                self._alpha = low_pass_coefficient(self.bandwidth_hz, period)
                state = self.DeclareDiscreteState(size)
                declare_periodic_update(self, period, 0.0, self._update)
                self.DeclareStateOutputPort("y", state)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._size, other.bandwidth_hz, other.period, converter=converter)

        def DoCalcTimeDerivatives(self, context, derivatives):
            u = self.get_input_port(0).Eval(context)
            y = context.get_continuous_state_vector().CopyToVector()
            derivatives.get_mutable_vector().SetFromVector(self._rate * (u - y))

        def _update(self, context, discrete_state):
            u = self.get_input_port(0).Eval(context)
            y = context.get_discrete_state(0).get_value()
            discrete_state.get_mutable_vector(0).SetFromVector(y + self._alpha * (u - y))

        def set_initial_output(self, context, y0):
            """Set the filter's state (= output) in its own context."""
            if self.period is None:
                context.get_mutable_continuous_state_vector().SetFromVector(y0)
            else:
                context.get_mutable_discrete_state(0).SetFromVector(y0)

    return Impl


LowPassFilter = default_instantiation(LowPassFilter_)
