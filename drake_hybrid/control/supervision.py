"""Making, losing and re-acquiring contact: the contact supervisor.

The paper's law assumes the tool is on the constraint surface and stays there. A task that
starts in free space, or whose surface moves away, needs a supervisor that decides when the
hybrid law applies. ``ContactSupervisor`` is that state machine; the controller reads its phase
(``HybridController(..., guarded_move=...)``) and runs the guarded move off the surface::

    TARE ──(t >= tare_time)──► APPROACH ──(p >= contact_threshold |F_d|)──► CONTACT
    hold still; the            guarded move at s along n_C                  the hybrid law
    conditioner tares            │     ▲                                      │
                                 │     └──(p < loss_threshold |F_d| for loss_dwell)──┘
                                 │ travel > max_travel
                                 ▼
                               HOLD ──(p >= contact_threshold |F_d|)──► CONTACT
                               hold still, wait

p = F . F_d / |F_d| is the measured force along the commanded one (|F_d| when the force loop
has converged), over the force-controlled rows of C; travel = n_C . (C - C_entry), with
n_C = -F_d / |F_d| the pressing direction in C's coordinates and C_entry the constraint value
when APPROACH began. While the measured wrench is invalid (a NaN from the wrench conditioner:
a sensor dropout longer than it bridges) nothing changes and the timers hold. Anti-windup off
the surface: the controller freezes xi in every phase but CONTACT, so a lost contact does not
wind up the force integral; on re-contact xi resumes from its value before the loss.

The guarded move servoes C to the approach reference C_r (the ``approach_reference`` output):
C_r = C_entry when APPROACH begins, C_r += h s n_C every period in APPROACH (it moves at the
approach speed s into the surface whether C follows or not), and C_r stands still in TARE, HOLD
and CONTACT, while the wrench is invalid, and once it is max_travel + 2 s / K_a from C_entry
(the travel's bound: a guarded move blocked short of the threshold, by an obstacle or a sensor
that reads nothing, then presses with at most about Lambda K_a^2 times that, not ever harder).
The controller's guarded move, C-ddot = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r)
(``law.guarded_acceleration``), is a velocity servo with integral action: C - C_r is the integral
of its velocity error since APPROACH began (reset there, unused in CONTACT). Against the surface
the pressing force keeps rising, at Lambda K_a^2 s per second, until it crosses the contact
threshold, whatever the arm's task inertia Lambda and the contact's damping; the velocity servo
alone stalls at a force proportional to Lambda.

A lost contact is re-acquired by the same guarded move: the arm moves along n_C at the
approach speed s until the force exceeds the contact threshold. The impact at re-contact is
that of a pad arriving at speed s (the peak force grows with s and the pad's stiffness; the
reliability figures in docs/reliability.md measure it).

Lift-off (a job's end; ``ContactSupervisor(..., lift_off=True)``): when the ``lift_off`` input
becomes 1 (e.g. ``systems.path_source.PathSource``'s ``path_done``), the supervisor leaves the
surface: phase HOLD (the controller's guarded move, no force command), C_entry = C_r = C there, and
C_r moving away from the surface at s (-n_C) until it is ``lift_height`` out, then standing; no
transition back to CONTACT however the pad touches on the way. The ``lifting`` output is 1 from then
on (the log's and plots' LIFT-OFF phase). The guarded move follows C_r with the lag 2 s / K_a of a
ramp (it has no speed feed-forward in HOLD).
"""

import sys
from dataclasses import dataclass
from typing import Union

import numpy as np
from numpy.typing import ArrayLike

from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import Context, LeafSystem_, OutputPort
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.sampling import SAMPLE_LEAD, declare_periodic_update, tick_offset
from drake_hybrid.core.arguments import MAX_TASK_SIZE, describe, instance, number, positive, vector
from drake_hybrid.core.errors import ArgumentError, ConfigError, check_fields
from drake_hybrid.core.hints import Array
from drake_hybrid.core.linalg import all_finite, value
from drake_hybrid.core.templates import default_instantiation


@dataclass
class SupervisionConfig:
    """The contact supervisor and the controller's guarded move (``ScenarioConfig.supervision``).

    A scenario builds the supervisor when ``enabled`` or when the start is off the surface
    (``start.in_contact: false``).

    enabled: build the supervisor (also built, whatever this says, when the start is off the surface).
    approach_speed: s, along the pressing direction, in units of C per second (m/s for the
        window and the sphere).
    approach_gain: K_a (1/s), the guarded move's bandwidth: its servo to the approach reference has a
        double pole at -K_a.
    contact_threshold: p at which contact is declared, as a fraction of |F_d|.
    loss_threshold: p (a fraction of |F_d|) below which (for ``loss_dwell`` seconds) contact is declared lost.
    loss_dwell: s the force must stay below ``loss_threshold`` before contact is declared lost.
    max_travel: how far (units of C) the guarded move may go without finding the surface.
    tare_time: s; > 0 starts in TARE (needs ``sensor.condition``) when the start is in free space.
    lift_height: how far (units of C) a lift-off takes the pad from the surface (a job's end).
    """

    enabled: bool = False
    approach_speed: float = 0.02
    approach_gain: float = 30.0
    contact_threshold: float = 0.3
    loss_threshold: float = 0.1
    loss_dwell: float = 0.01
    max_travel: float = 0.05
    tare_time: float = 0.0
    lift_height: float = 0.01

    def validate(self) -> "SupervisionConfig":
        """ValueError naming the first bad field."""
        check_fields(self, "supervision.", positive=("approach_gain", "loss_dwell", "max_travel", "lift_height"),
                     nonnegative=("approach_speed", "tare_time"))
        if not 0 < float(self.loss_threshold) < float(self.contact_threshold) <= 1:
            raise ConfigError("supervision thresholds must satisfy 0 < loss_threshold < contact_threshold <= 1 "
                             f"(fractions of |F_d|), got loss_threshold = {self.loss_threshold}, contact_threshold = "
                             f"{self.contact_threshold}")
        return self


@TemplateSystem.define("ContactSupervisor_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def ContactSupervisor_(T):

    class Impl(LeafSystem_[T]):
        """The contact state machine of the module docstring, sampled with the controller.

        .. pydrake_system::

            name: ContactSupervisor
            input_ports:
            - force
            - desired_force
            - constraint_value
            - measured_wrench
            - lift_off (only with lift_off)
            output_ports:
            - contact_phase
            - contact_count
            - approach_reference
            - lifting

        ==================  ====  ==============================================================
        force               m     F (the controller's ``force`` output)
        desired_force       m     F_d
        constraint_value    m     C(r) (the controller's ``constraint_value`` output)
        measured_wrench     6     the wrench the controller reads (NaN entries: no decision)
        lift_off            1     >= 0.5: leave the surface (only with ``lift_off``)
        contact_phase       1     phases.ContactPhase (state)
        contact_count       1     how many times CONTACT was entered (state)
        approach_reference  m     C_r, the guarded move's reference (state)
        lifting             1     1 once a lift-off has begun (state)
        ==================  ====  ==============================================================

        Discrete state [phase, timer, contact count, C_entry (m), C_r (m), lifting], updated every ``period`` at
        the controller's tick (k h - SAMPLE_LEAD h), from the controller's outputs at that tick:
        a transition takes effect at the next tick (one period of latency).

        The AutoDiffXd instance decides on the values (a phase has no derivative); it exists so
        that a diagram containing the supervisor converts.

        Args:
            config: SupervisionConfig.
            force_size: m.
            kinematic_rows: rows of C held kinematically (excluded from p and n_C).
            period: the control period h (s).
            initial_phase: the phase at t = 0 (a ContactPhase).
            lift_off: declare the ``lift_off`` input (a job's end: leave the surface, module docstring).
        """

        def _construct(self, config, force_size, kinematic_rows, period, initial_phase=ContactPhase.CONTACT,
                       lift_off=False, converter=None):
            LeafSystem_[T].__init__(self, converter)
            owner = "ContactSupervisor"
            instance(config, "config", owner, SupervisionConfig).validate()
            period = positive(period, "period", owner, unit="s")
            m = number(force_size, "force_size", owner, low=1, high=MAX_TASK_SIZE, integer=True)
            self.config, self.force_size, self.period = config, m, period
            rows = vector(kinematic_rows, "kinematic_rows", owner)
            if any(not (row.is_integer() and 0 <= row < m) for row in rows):
                raise ArgumentError(f"{owner}: kinematic_rows must be row indices in 0..{m - 1}, got "
                                    f"{describe(kinematic_rows)}")
            self.kinematic_rows = tuple(int(i) for i in rows)
            if initial_phase not in tuple(ContactPhase) + tuple(int(phase) for phase in ContactPhase):
                raise ArgumentError(f"{owner}: initial_phase must be a ContactPhase "
                                    f"({', '.join(phase.name for phase in ContactPhase)}), got {describe(initial_phase)}")
            self.initial_phase = ContactPhase(initial_phase)
            self._force_controlled = np.ones(m)
            self._force_controlled[list(self.kinematic_rows)] = 0.0
            self._force_port = self.DeclareVectorInputPort("force", m)
            self._desired_force_port = self.DeclareVectorInputPort("desired_force", m)
            self._constraint_port = self.DeclareVectorInputPort("constraint_value", m)
            self._wrench_port = self.DeclareVectorInputPort("measured_wrench", 6)
            self.lift_off = bool(lift_off)
            self._lift_port = self.DeclareVectorInputPort("lift_off", 1) if self.lift_off else None
            initial = np.zeros(3 + 2 * m + 1)
            initial[0] = float(self.initial_phase)
            self._state_index = self.DeclareDiscreteState(initial)
            declare_periodic_update(self, self.period, tick_offset(self.period), self._update)
            self.DeclareVectorOutputPort("contact_phase", 1, self._calc_phase, prerequisites_of_calc={self.xd_ticket()})
            self.DeclareVectorOutputPort("contact_count", 1, self._calc_count, prerequisites_of_calc={self.xd_ticket()})
            self.DeclareVectorOutputPort("approach_reference", m, self._calc_reference,
                                         prerequisites_of_calc={self.xd_ticket()})
            self.DeclareVectorOutputPort("lifting", 1, self._calc_lifting, prerequisites_of_calc={self.xd_ticket()})

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.config, other.force_size, other.kinematic_rows, other.period,
                            other.initial_phase, other.lift_off, converter=converter)

        def get_contact_phase_output_port(self) -> OutputPort:
            return self.GetOutputPort("contact_phase")

        def set_initial_state(self, context: Context, phase: Union[ContactPhase, int],
                              constraint_value: ArrayLike) -> None:
            """Start in ``phase`` with C_entry = C_r = ``constraint_value`` (C at the start: the travel
            and the reference of a first APPROACH count from there), timers and count reset. A loop built
            by hand must call it (``scenario.start`` does): the default state has C_r = 0, the surface,
            which a start in TARE or HOLD would be servoed to."""
            constraint_value = np.asarray(value(constraint_value), dtype=float)
            if constraint_value.shape != (self.force_size,):
                raise ValueError(f"ContactSupervisor: constraint_value must have {self.force_size} entries, got "
                                 f"{constraint_value.shape}")
            state: Array = np.concatenate([[float(ContactPhase(phase)), 0.0, 0.0], constraint_value, constraint_value,
                                           [0.0]])
            context.SetDiscreteState(0, state)

        def _calc_phase(self, context, output):
            output.SetFromVector(context.get_discrete_state(0).CopyToVector()[:1])

        def _calc_count(self, context, output):
            output.SetFromVector(context.get_discrete_state(0).CopyToVector()[2:3])

        def _calc_reference(self, context, output):
            m = self.force_size
            output.SetFromVector(context.get_discrete_state(0).CopyToVector()[3 + m:3 + 2 * m])

        def _calc_lifting(self, context, output):
            output.SetFromVector(context.get_discrete_state(0).CopyToVector()[3 + 2 * self.force_size:])

        def next_state(self, state: Array, force: Array, desired_force: Array, constraint_value: Array,
                       wrench_valid: bool, lift: bool = False) -> Array:
            """The transition of the module docstring (floats): the state after one period (``lift``: the
            lift_off input is set; a state without the lifting entry is returned without it)."""
            config, h, m = self.config, self.period, self.force_size
            phase, timer, count = ContactPhase(int(state[0])), float(state[1]), float(state[2])
            entry, reference = np.array(state[3:3 + m], dtype=float), np.array(state[3 + m:3 + 2 * m], dtype=float)
            tail = [float(state[3 + 2 * m])] if len(state) > 3 + 2 * m else []     # [lifting]
            commanded = desired_force * self._force_controlled
            magnitude = float(np.linalg.norm(commanded))
            if magnitude == 0:                      # no pressing direction: nothing to supervise
                return np.concatenate([[float(phase), timer, count], entry, reference, tail])
            pressing = float(force @ commanded) / magnitude if wrench_valid else None     # p
            direction = -commanded / magnitude                                             # n_C
            touching = pressing is not None and pressing >= config.contact_threshold * magnitude
            if tail and (lift or tail[0] > 0.5):
                # Lift-off: HOLD, C_r away from the surface at s from C there, up to lift_height out.
                if tail[0] < 0.5:
                    phase, timer, entry, tail = ContactPhase.HOLD, 0.0, constraint_value.copy(), [1.0]
                    reference = entry.copy()
                else:
                    away = min(-direction @ (reference - entry) + h * config.approach_speed, config.lift_height)
                    reference = entry - away * direction
            elif phase is ContactPhase.TARE:
                timer += h
                if timer >= config.tare_time - 0.5 * h:
                    phase, timer, entry = ContactPhase.APPROACH, 0.0, constraint_value.copy()
                    reference = entry.copy()
            elif phase in (ContactPhase.APPROACH, ContactPhase.HOLD):
                if touching:
                    phase, timer, count = ContactPhase.CONTACT, 0.0, count + 1
                elif phase is ContactPhase.APPROACH and direction @ (constraint_value - entry) > config.max_travel:
                    phase, timer = ContactPhase.HOLD, 0.0
                elif phase is ContactPhase.APPROACH and wrench_valid:
                    # C_r moves at s n_C, no further than max_travel + 2 s / K_a from C_entry (the travel's
                    # documented bound): blocked short of the threshold (an obstacle, a sensor reading 0),
                    # the guarded move presses with at most about Lambda K_a^2 times that, not more and more.
                    limit = config.max_travel + 2.0 * config.approach_speed / config.approach_gain
                    travel = min(direction @ (reference - entry) + h * config.approach_speed, limit)
                    reference = entry + travel * direction
            elif pressing is not None:              # CONTACT, with a valid measurement
                if pressing < config.loss_threshold * magnitude:
                    timer += h
                    if timer >= config.loss_dwell - 0.5 * h:
                        phase, timer, entry = ContactPhase.APPROACH, 0.0, constraint_value.copy()
                        reference = entry.copy()
                else:
                    timer = 0.0
            return np.concatenate([[float(phase), timer, count], entry, reference, tail])

        def _update(self, context, discrete_state):
            state = value(context.get_discrete_state(0).CopyToVector())
            force = value(self._force_port.Eval(context))
            wrench_valid = all_finite(self._wrench_port.Eval(context)) and all_finite(force)
            lift = self._lift_port is not None and float(value(self._lift_port.Eval(context))[0]) >= 0.5
            new_state = self.next_state(state, force, value(self._desired_force_port.Eval(context)),
                                        value(self._constraint_port.Eval(context)), wrench_valid, lift)
            discrete_state.get_mutable_vector(0).SetFromVector(new_state)

    return Impl


ContactSupervisor = default_instantiation(ContactSupervisor_)
