"""Gains changed at run time without a jump in the torque (bumpless transfer).

The law's gains enter through two lines (docs/theory.md, control/law.py)::

    a_p = r-ddot_pd - K_v e_v - K_p e_p          (3.1-12, Remark 3)
    u_f = -F_d + K_fp e_f + K_fi xi               (3.1-12)

so at a change (K_v, K_p, K_fp, K_fi) -> (K_v', K_p', K_fp', K_fi') the integrals of the new law can
be chosen to give the same a_p and u_f, hence the same torque, at the change::

    xi'  = K_fi'^-1 (K_fi xi + (K_fp - K_fp') e_f)
    e_p' = K_p'^-1  (K_p e_p + (K_v - K_v') e_v)          (position and impedance modes)

after which the integrals evolve under the new gains and the errors decay with the new design.
In velocity-force mode there is no e_p to absorb a change of K_v: the step (K_v - K_v') e_v remains
(the torque-rate limit spreads it). Other gain fields (null-space damping, ...) are not transferred;
nor is the impedance mass M_d: changing it steps a_p by (M_d'^-1 - M_d^-1) F_v in impedance mode.

``GainSelector`` passes on the actuation of the law active at each tick; each gain set is its own
``HybridController`` (unchanged), all fed the same inputs, and ``bumpless_integrals`` gives the new
one's state at the change (``ControllerStation.before_tick`` applies it).
"""

import numpy as np

from pydrake.systems.framework import LeafSystem


def _solve(matrix, vector):
    return np.linalg.lstsq(matrix, vector, rcond=None)[0]


def bumpless_integrals(old_gains, new_gains, force_integral, position_error, force_error, velocity_error,
                       integrates_position):
    """(xi', e_p') of the new law that give the old law's a_p and u_f (module docstring)."""
    xi = _solve(new_gains.force_integral,
                old_gains.force_integral @ force_integral
                + (old_gains.force_proportional - new_gains.force_proportional) @ force_error)
    if not integrates_position:
        return xi, np.zeros(0)
    e_p = _solve(new_gains.position, old_gains.position @ position_error
                 + (old_gains.velocity - new_gains.velocity) @ velocity_error)
    return xi, e_p


class GainSelector(LeafSystem):
    """The actuation of the law active at the tick: law i from tick ``change_ticks[i - 1]`` on.

    .. pydrake_system::

        name: GainSelector
        input_ports:
        - actuation_0
        - actuation_1
        - ...
        output_ports:
        - actuation
    """

    def __init__(self, num_joints, period, change_ticks):
        LeafSystem.__init__(self)
        self.period = float(period)
        self.change_ticks = [int(k) for k in change_ticks]
        self._inputs = [self.DeclareVectorInputPort(f"actuation_{i}", num_joints)
                        for i in range(len(self.change_ticks) + 1)]
        self.DeclareVectorOutputPort("actuation", num_joints, self._calc)

    def active(self, time):
        """The index of the law active at ``time`` (its tick: round(t / h))."""
        tick = int(round(time / self.period))
        return sum(1 for k in self.change_ticks if tick >= k)

    def _calc(self, context, output):
        output.SetFromVector(self._inputs[self.active(context.get_time())].Eval(context))
