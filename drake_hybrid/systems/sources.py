"""Desired motion and force for the controller (paper section 2.3, docs/theory.md §4).

``DesiredFieldSource``
    evaluates a desired velocity field Y_d : N -> TN (2.3-1) and a force field
    F_d : N -> R^m (2.3-4) at the measured configuration and outputs
    r-dot_pd = E_p(r) Y_d(r), its derivative along the actual trajectory
    r-ddot_pd = E_p-dot Y_d + E_p (dY_d/dr) r-dot (docs/theory.md §4;
    computable from measurements) and F_d(r).
``ProfileSource``
    time profiles r-dot_pd(t), r-ddot_pd(t) = d/dt r-dot_pd(t) and F_d(t).
``PseudoVelocitySource``
    the paper's desired pseudo-velocity (3.3-8), (3.3-16) for its orthogonal
    E_p, built from a true-velocity command r-dot_td(t) (docs/theory.md §6), with
    the unmeasurable Euler-acceleration term of r-ddot_pd dropped (the naive
    implementation; Option A, E = [E_t; E_f], is exact and the default).

``Profile`` is the typed (YAML-loadable) description of a time profile.
"""

import math
import sys
from dataclasses import dataclass, field
from typing import List, Tuple

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.core.arguments import MAX_TASK_SIZE, describe, instance, nonnegative, number, positive, vector
from drake_hybrid.core.errors import ConfigError, DimensionError, ForceSignError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.kinematics import declare_cached_value, declare_task_input
from drake_hybrid.core.linalg import value
from drake_hybrid.core.projections import pseudo_desired_velocity
from drake_hybrid.core.symbolic import CompiledFunction, to_sympy_matrix
from drake_hybrid.core.templates import default_instantiation


@dataclass
class Profile:
    """A vector time profile and its derivative.

    kind:
      ``constant``     value
      ``smooth_step``  from ``value`` to ``final_value`` over [start_time, start_time + duration]
                       with a quintic blend (continuous velocity and acceleration)
      ``sine``         value + amplitude sin(2 pi frequency (t - start_time))

    value: the profile's value (its rows' units: m/s, rad/s, N, ...), one entry per row.
    final_value: smooth_step: the value after the step (the rows' units).
    amplitude: sine: the amplitude (the rows' units).
    frequency: sine: Hz.
    start_time: s, when the step or the sine starts.
    duration: s, smooth_step: how long the blend takes.
    """

    kind: str = "constant"
    value: List[float] = field(default_factory=list)
    final_value: List[float] = field(default_factory=list)
    amplitude: List[float] = field(default_factory=list)
    frequency: float = 0.0
    start_time: float = 0.0
    duration: float = 1.0

    KINDS = ("constant", "smooth_step", "sine")

    def check_kind(self, what: str) -> None:
        """ConfigError naming ``what``.kind if it is not one of KINDS (the sizes are checked by ``validate``)."""
        if self.kind not in self.KINDS:
            raise ConfigError(f"{what}.kind must be one of {', '.join(self.KINDS)}, got {describe(self.kind)}")

    def validate(self, size: int, what: str) -> None:
        """Raise a typed error naming ``what``.field for a field that does not make a profile of ``size``
        entries: the kind, entries that are not finite numbers, the sizes, a duration <= 0."""
        self.check_kind(what)
        owner = "Profile"
        entries = {"value": self.value}
        if self.kind == "smooth_step":
            entries["final_value"] = self.final_value
        if self.kind == "sine":
            entries["amplitude"] = self.amplitude
        for name, given in entries.items():
            array = vector(given, f"{what}.{name}", owner, error=ConfigError)
            if array.size != size:
                raise DimensionError(f"{what}: {name} must have {size} entries, got {array.size}")
        number(self.start_time, f"{what}.start_time", owner, unit="s", error=ConfigError)
        if self.kind == "smooth_step":
            positive(self.duration, f"{what}.duration", owner, unit="s", error=ConfigError)
        if self.kind == "sine":
            nonnegative(self.frequency, f"{what}.frequency", owner, unit="Hz", error=ConfigError)

    def bounds(self) -> Tuple[Array, Array]:
        """(lowest, highest) value of each row over the profile's whole course, t >= 0."""
        base = np.asarray(self.value, dtype=float)
        if self.kind == "smooth_step":                  # the quintic blend is monotone from value to final_value
            final = np.asarray(self.final_value, dtype=float)
            return np.minimum(base, final), np.maximum(base, final)
        if self.kind == "sine" and self.frequency > 0:  # every phase comes round
            swing = np.abs(np.asarray(self.amplitude, dtype=float))
            return base - swing, base + swing
        return base, base

    def check_keeps_sign(self, what: str) -> None:
        """ForceSignError naming ``what`` if a row of this (desired force) profile takes both signs over
        its course: a contact only pushes, so a row of F_d that presses at one time would pull at
        another (F_d is the force ON the robot in E_f's coordinates). Zero (letting go) is allowed."""
        lowest, highest = self.bounds()
        for row, (low, high) in enumerate(zip(lowest, highest)):
            if low < 0 < high:
                if self.kind == "smooth_step":
                    course = (f"a smooth_step from {self.value[row]:g} to {self.final_value[row]:g} over "
                              f"t = {self.start_time:g}..{self.start_time + self.duration:g} s")
                else:
                    course = f"a sine of {self.value[row]:g} +- {abs(self.amplitude[row]):g}"
                raise ForceSignError(
                    f"{what}: row {row} changes sign over its course ({course}: from {low:g} to {high:g}); a contact "
                    "only pushes, so F_d (the force ON the robot in E_f's coordinates) must keep one sign on every row "
                    "(it may reach 0)")

    def evaluate(self, t: float) -> Tuple[Array, Array]:
        """(value, time derivative) at time t (floats)."""
        base = np.asarray(self.value, dtype=float)
        if self.kind == "constant":
            return base, np.zeros_like(base)
        if self.kind == "smooth_step":
            s = min(max((t - self.start_time) / self.duration, 0.0), 1.0)
            blend = s**3 * (10 - 15 * s + 6 * s * s)
            blend_rate = 30 * s * s * (1 - s) ** 2 / self.duration
            delta = np.asarray(self.final_value, dtype=float) - base
            return base + blend * delta, blend_rate * delta
        omega = 2 * math.pi * self.frequency
        amplitude = np.asarray(self.amplitude, dtype=float)
        phase = omega * (t - self.start_time)
        return base + amplitude * math.sin(phase), amplitude * omega * math.cos(phase)


def _checked_profiles(owner, velocity_profile, force_profile, velocity_size, force_size):
    """The sizes (k, m) as integers, both profiles checked (Profile, validated for their sizes)."""
    velocity_size = number(velocity_size, "velocity_size", owner, low=0, high=MAX_TASK_SIZE, integer=True)
    force_size = number(force_size, "force_size", owner, low=1, high=MAX_TASK_SIZE, integer=True)
    for name, profile, size in (("velocity_profile", velocity_profile, velocity_size),
                                ("force_profile", force_profile, force_size)):
        instance(profile, name, owner, Profile, what="a Profile (e.g. Profile(kind='constant', value=[...]))")
        profile.validate(size, name)
    return velocity_size, force_size


@TemplateSystem.define("ProfileSource_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def ProfileSource_(T):

    class Impl(LeafSystem_[T]):
        """Time profiles of the desired velocity and force.

        .. pydrake_system::

            name: ProfileSource
            output_ports:
            - desired_velocity
            - desired_acceleration
            - desired_force

        desired_acceleration is the exact time derivative of desired_velocity.
        """

        def _construct(self, velocity_profile, force_profile, velocity_size, force_size, converter=None):
            LeafSystem_[T].__init__(self, converter)
            velocity_size, force_size = _checked_profiles("ProfileSource", velocity_profile, force_profile,
                                                          velocity_size, force_size)
            self.velocity_profile, self.force_profile = velocity_profile, force_profile
            self._sizes = (velocity_size, force_size)
            # A constant profile's outputs depend on nothing: Drake computes them once per context (no
            # Python call at every tick and every logged sample); the others depend on time.
            velocity, force = ({self.nothing_ticket() if profile.kind == "constant" else self.time_ticket()}
                               for profile in (velocity_profile, force_profile))
            self.DeclareVectorOutputPort("desired_velocity", velocity_size, self._calc_velocity,
                                         prerequisites_of_calc=velocity)
            self.DeclareVectorOutputPort("desired_acceleration", velocity_size, self._calc_acceleration,
                                         prerequisites_of_calc=velocity)
            self.DeclareVectorOutputPort("desired_force", force_size, self._calc_force,
                                         prerequisites_of_calc=force)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.velocity_profile, other.force_profile, *other._sizes, converter=converter)

        def _time(self, context):
            return float(value(context.get_time()))

        def _calc_velocity(self, context, output):
            output.SetFromVector(self.velocity_profile.evaluate(self._time(context))[0])

        def _calc_acceleration(self, context, output):
            output.SetFromVector(self.velocity_profile.evaluate(self._time(context))[1])

        def _calc_force(self, context, output):
            output.SetFromVector(self.force_profile.evaluate(self._time(context))[0])

    return Impl


ProfileSource = default_instantiation(ProfileSource_)


@TemplateSystem.define("PseudoVelocitySource_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def PseudoVelocitySource_(T):

    class Impl(LeafSystem_[T]):
        """The paper's desired pseudo-velocity for its E_p (docs/theory.md §6), naive form.

        .. pydrake_system::

            name: PseudoVelocitySource
            input_ports:
            - estimated_state
            output_ports:
            - desired_velocity
            - desired_acceleration
            - desired_force

        With the paper's E_p and the true-velocity rows E_t, the task is
        specified as r-dot_td(t) (``velocity_profile``) and the controller is fed

            r-dot_pd  = r-dot_td + (E_p - E_t) r-dot                   (3.3-8), (3.3-16) corrected
            r-ddot_pd = r-ddot_td + (E_p-dot - E_t-dot) r-dot          [+ (E_p - E_t) r-ddot: dropped]

        so that e_p' = E_p r-dot - r-dot_pd = E_t r-dot - r-dot_td exactly. The
        dropped term holds the actual Euler-angle accelerations (phi-ddot for
        the crank), which are not measurable and depend on the torque itself;
        resolving that implicit equation exactly gives Option A's torque
        (the true-velocity rows, ``projections.crank_true_velocity_projection``
        and ``sphere_true_velocity_projection``). Dropping it (this source) is what a
        direct implementation of the paper does; it does not realize the
        designed loop.
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, paper_projection, true_projection,
                       velocity_profile, force_profile, force_size, converter=None):
            LeafSystem_[T].__init__(self, converter)
            k = paper_projection.size
            if true_projection.size != k:
                raise DimensionError(f"paper E_p has {k} rows but E_t has {true_projection.size}")
            _, force_size = _checked_profiles("PseudoVelocitySource", velocity_profile, force_profile, k, force_size)
            end_effector_point = vector(end_effector_point, "end_effector_point", "PseudoVelocitySource", 3, unit="m")
            self._arguments = (plant, end_effector_frame, end_effector_point, paper_projection, true_projection,
                               velocity_profile, force_profile, force_size)
            self.paper_projection, self.true_projection = paper_projection, true_projection
            self.velocity_profile, self.force_profile = velocity_profile, force_profile
            _, self.kinematics, _, self._plant_context_cache = declare_task_input(
                self, T, plant, end_effector_frame, end_effector_point, paper_projection.chart)
            # Both projections at the measured state, once per state (read by two outputs).
            self._rows = declare_cached_value(self, "E_p and E_t", lambda context: self._calc_rows(
                self._plant_context_cache.Eval(context)), {self._plant_context_cache.ticket()})
            prerequisites = {self._rows.ticket(), self.time_ticket()}
            self.DeclareVectorOutputPort("desired_velocity", k, self._calc_velocity, prerequisites_of_calc=prerequisites)
            self.DeclareVectorOutputPort("desired_acceleration", k, self._calc_acceleration,
                                         prerequisites_of_calc=prerequisites)
            self.DeclareVectorOutputPort("desired_force", force_size, self._calc_force,
                                         prerequisites_of_calc={self.time_ticket()})

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._arguments, converter=converter)

        def _calc_rows(self, plant_context):
            task = self.kinematics.evaluate(plant_context)
            x, nu = task.configuration, task.velocity
            E_p, E_p_dot_nu = self.paper_projection.evaluate(x, nu)
            E_t, E_t_dot_nu = self.true_projection.evaluate(x, nu)
            return nu, E_p, E_t, E_p_dot_nu - E_t_dot_nu

        def _calc_velocity(self, context, output):
            nu, E_p, E_t, _ = self._rows.Eval(context)
            true_velocity = self.velocity_profile.evaluate(float(value(context.get_time())))[0]
            output.SetFromVector(pseudo_desired_velocity(E_p, E_t, true_velocity, nu))   # (3.3-8)

        def _calc_acceleration(self, context, output):
            difference_rate = self._rows.Eval(context)[3]
            true_acceleration = self.velocity_profile.evaluate(float(value(context.get_time())))[1]
            output.SetFromVector(true_acceleration + difference_rate)                 # naive: no (E_p - E_t) r-ddot

        def _calc_force(self, context, output):
            output.SetFromVector(self.force_profile.evaluate(float(value(context.get_time())))[0])

    return Impl


PseudoVelocitySource = default_instantiation(PseudoVelocitySource_)


@TemplateSystem.define("DesiredFieldSource_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def DesiredFieldSource_(T):

    class Impl(LeafSystem_[T]):
        """Desired velocity field Y_d(r) (2.3-1) and force field F_d(r) (2.3-4) on N.

        .. pydrake_system::

            name: DesiredFieldSource
            input_ports:
            - estimated_state
            output_ports:
            - desired_velocity
            - desired_acceleration
            - desired_force

        Outputs r-dot_pd = E_p Y_d, r-ddot_pd = E_p-dot Y_d + E_p (dY_d/dx) x-dot
        and F_d(x), all at the measured end-effector configuration x.

        Args:
            plant, end_effector_frame, end_effector_point: as for HybridController.
            constraint_space: the controller's ConstraintSpace (gives E_p).
            velocity_field: d expressions in the chart's configuration symbols
                (a tangent vector field in the chart's velocity coordinates).
            force_field: m expressions (or numbers) in the same symbols.
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, constraint_space, velocity_field,
                       force_field, converter=None):
            LeafSystem_[T].__init__(self, converter)
            chart = constraint_space.chart
            self._float_plant = plant
            self._end_effector_point = vector(end_effector_point, "end_effector_point", "DesiredFieldSource", 3,
                                              unit="m")
            self.constraint_space = constraint_space
            self.velocity_field, self.force_field = velocity_field, force_field
            d, m, k = chart.velocity_size, constraint_space.force_size, constraint_space.velocity_size
            symbols = chart.configuration_symbols
            Y = to_sympy_matrix(velocity_field, symbols, what="velocity field")
            F = to_sympy_matrix(force_field, symbols, what="force field")
            if Y.shape != (d, 1):
                raise DimensionError(f"velocity field must have d = {d} entries, got {Y.shape[0] * Y.shape[1]}")
            if F.shape != (m, 1):
                raise DimensionError(f"force field must have m = {m} entries, got {F.shape[0] * F.shape[1]}")
            self._velocity_field = CompiledFunction("Y_d", [symbols], Y, vector=True)
            self._velocity_field_jacobian = CompiledFunction("dY_d/dx", [symbols], Y.jacobian(list(symbols)))
            self._force_field = CompiledFunction("F_d", [symbols], F, vector=True)
            self._float_frame, self.kinematics, _, self._plant_context_cache = declare_task_input(
                self, T, plant, end_effector_frame, end_effector_point, chart)
            # x, nu, E_p and E_p-dot at the measured state, once per state (read by three outputs).
            self._task = declare_cached_value(self, "x, nu, E_p, E_p-dot", lambda context: self._calc_task(
                self._plant_context_cache.Eval(context)), {self._plant_context_cache.ticket()})
            prerequisites = {self._task.ticket()}
            self.DeclareVectorOutputPort("desired_velocity", k, self._calc_velocity, prerequisites_of_calc=prerequisites)
            self.DeclareVectorOutputPort("desired_acceleration", k, self._calc_acceleration,
                                         prerequisites_of_calc=prerequisites)
            self.DeclareVectorOutputPort("desired_force", m, self._calc_force, prerequisites_of_calc=prerequisites)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._float_plant, other._float_frame, other._end_effector_point,
                            other.constraint_space, other.velocity_field, other.force_field, converter=converter)

        def _calc_task(self, plant_context):
            task = self.kinematics.evaluate(plant_context)
            x, nu = task.configuration, task.velocity
            return (x, nu) + tuple(self.constraint_space.velocity_projection.matrix_and_rate(x, nu))

        def _calc_velocity(self, context, output):
            x, _, E_p, _ = self._task.Eval(context)
            output.SetFromVector(E_p @ self._velocity_field(x))

        def _calc_acceleration(self, context, output):
            x, nu, E_p, E_p_dot = self._task.Eval(context)
            x_dot = self.constraint_space.chart.configuration_rate_at(x, nu)
            Y = self._velocity_field(x)
            output.SetFromVector(E_p_dot @ Y + E_p @ (self._velocity_field_jacobian(x) @ x_dot))

        def _calc_force(self, context, output):
            output.SetFromVector(self._force_field(self._task.Eval(context)[0]))

    return Impl


DesiredFieldSource = default_instantiation(DesiredFieldSource_)
