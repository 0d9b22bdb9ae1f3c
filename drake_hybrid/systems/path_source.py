"""The desired motion and force of a path over the workpiece (``core.paths.SurfacePath``).

``PathSource`` turns the path's reference, the pad centre c_d(t) on the offset surface C = 0 with its
velocity and acceleration and the surface's normal n there, into the controller's commands in E_p's
coordinates (PoseChart: x = (p, R), nu = (v, omega)).

The reference frame R_d has the approach vector a_d = -n and the tool's x axis along ``heading``
turned into the tangent plane (``reference_frame``: omega_d, omega-dot_d from n, n-dot, n-ddot).
The reference point follows the pad at its depth: a pressed compliant pad sits delta = -C_1 / |grad C_1|
inside C = 0 (its compression, which the force loop sets), so the reference is
c_r = c_d - delta n with c_r-dot = c_d-dot - delta n-dot (and c_r-ddot = c_d-ddot - delta-dot n-dot -
delta n-ddot, delta-dot from C_1-dot = E_f,1 nu and E_f-dot,1 nu, measured: exactly the derivative). With the measured configuration x and
twist nu (docs/theory.md §4.2)::

    nu_r      = (c_r-dot, omega_d),  nu-dot_r = (c_r-ddot, omega-dot_d)
    r-dot_pd  = E_p(x) nu_r                                   the velocity rows' command
    r-ddot_pd = E_p-dot(x, nu) nu_r + E_p(x) nu-dot_r          its derivative along the actual motion
    e_p       = E_p(x) (P (c - c_r), vee(R R_d^T - R_d R^T) / 2)   the position error against the path
    F_d       = F(s) on the force row (the normal force, N), ``moments`` on the force-controlled
                orientation rows (a flat tool's, N m; zero by default), 0 on the others

with P = I - n n^T, so that d/dt e_p = e_p' = E_p nu - r-dot_pd to first order. (delta is the
pad's distance from C = 0: exact for the signed distances of ``core.surfaces``; P removes any normal
remainder from e_p, so a pad pressed at rest is an equilibrium.) Measured from c_d instead, the compression
would count as a position error wherever E_p's rows are not tangent (u . n delta: 0.42 mm at the sphere
cap's 28 deg), and measured from c_d but projected onto the tangent plane its rate would differ from
e_p' by u . delta n-dot: 1 mm/s on the bump's top (delta 1 mm, n turning at 1 rad/s), which K_p, K_v
turn into a steady error K_v delta |n-dot| / K_p (0.15 mm). With the view rows of
``core.surfaces.view_projection`` the translational rows of e_p are u . (c - c_r) and v . (c - c_r).
In position-force mode the controller takes e_p from here (its ``path_position_error`` input) instead
of the integral of e_p', so the position error is measured against the path and cannot drift.

The path's clock: t_path = t - t_0. Without ``wait_for_contact`` t_0 = ``dwell``; with it (a job
that starts off the surface) t_0 is set at the first control tick that reads CONTACT on
``contact_phase`` (plus ``dwell``, time for the force to settle before moving), held in
discrete state: before it the reference holds the first point at rest (the guarded approach
goes to it). ``path_done`` is 1 once the path has ended (the contact supervisor's lift-off
input).
"""

import sys

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import sqrt
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.sampling import declare_periodic_update, tick_offset
from drake_hybrid.core.arguments import boolean, describe, instance, nonnegative, number, positive, vector
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.kinematics import declare_cached_value, declare_task_input
from drake_hybrid.core.linalg import value
from drake_hybrid.core.paths import SurfacePath
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.templates import default_instantiation

NOT_STARTED = 1.0e9          # t_0 before the first contact


def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def reference_rotation(normal, heading, owner="reference_rotation"):
    """R_d = [o_1, a x o_1, a] with a = -normal and o_1 the heading turned into the tangent plane;
    ArgumentError (naming ``owner``) for a heading or normal that is not 3 finite numbers, a zero normal
    or a heading along the normal."""
    normal = vector(normal, "normal", owner, 3)
    if not np.linalg.norm(normal) > 1e-12:
        raise ArgumentError(f"{owner}: normal must be a nonzero vector, got {normal.tolist()}")
    return reference_frame(normal / np.linalg.norm(normal), np.zeros(3), np.zeros(3),
                           vector(heading, "heading", owner, 3), owner)[0]


def reference_frame(normal, normal_rate, normal_acceleration, heading, owner="reference_frame"):
    """(R_d, omega_d, omega-dot_d) of the reference frame R_d = [o_1, o_2, a]: a = -n, o_1 = g / |g| with
    g = h - (h . a) a (the heading h in the tangent plane), o_2 = a x o_1; from n, n-dot, n-ddot.

    omega = a x a-dot + sigma a, where the spin sigma = o_1-dot . o_2 = -(h . a)(a-dot . o_2) / |g|
    keeps o_1 in the plane of a and h; omega-dot = a x a-ddot + sigma-dot a + sigma a-dot. ``normal`` is a
    unit vector (a path's); ArgumentError (naming ``owner``) for non-finite entries or a heading along it."""
    h = np.asarray(heading, dtype=float)
    a, a_dot, a_ddot = -np.asarray(normal, dtype=float), -np.asarray(normal_rate), -np.asarray(normal_acceleration)
    vectors = (("heading", h), ("normal", a), ("normal_rate", a_dot), ("normal_acceleration", a_ddot))
    if any(entries.shape != (3,) for _, entries in vectors) or not np.isfinite(np.concatenate([h, a, a_dot,
                                                                                               a_ddot])).all():
        name, entries = next((name, entries) for name, entries in vectors
                             if entries.shape != (3,) or not np.all(np.isfinite(entries)))
        raise ArgumentError(f"{owner}: {name} must be a vector of 3 finite numbers, got {describe(entries)}")
    h_a = h @ a
    g = h - h_a * a
    length = np.sqrt(g @ g)
    if length < 1e-6 * max(1.0, np.sqrt(h @ h)):
        raise ArgumentError(f"{owner}: heading must be a direction not along the surface normal, got {h.tolist()} "
                            f"(normal {np.round(-a, 6).tolist()})")
    o1 = g / length
    o2 = _cross(a, o1)
    sigma = -h_a * (a_dot @ o2) / length
    omega = _cross(a, a_dot) + sigma * a
    length_dot = -h_a * (a_dot @ o1)
    sigma_dot = (-((h @ a_dot) * (a_dot @ o2) + h_a * (a_ddot @ o2 + a_dot @ _cross(omega, o2))) / length
                 + h_a * (a_dot @ o2) * length_dot / (length * length))
    omega_dot = _cross(a, a_ddot) + sigma_dot * a + sigma * a_dot
    return np.column_stack([o1, o2, a]), omega, omega_dot


def _vee(skew):
    return np.array([skew[2, 1], skew[0, 2], skew[1, 0]])


@TemplateSystem.define("PathSource_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def PathSource_(T):

    class Impl(LeafSystem_[T]):
        """The commands of a path over the workpiece (module docstring).

        .. pydrake_system::

            name: PathSource
            input_ports:
            - estimated_state
            - contact_phase (only with wait_for_contact)
            output_ports:
            - desired_velocity
            - desired_acceleration
            - desired_force
            - path_position_error
            - reference_position
            - reference_normal
            - path_error
            - path_progress
            - path_done

        ====================  ====  ==========================================================
        estimated_state       2n    [q; v] of the controller's plant
        contact_phase         1     phases.ContactPhase (the supervisor's), read at the ticks
        desired_velocity      k     r-dot_pd = E_p(x) nu_r
        desired_acceleration  k     r-ddot_pd = E_p-dot nu_r + E_p nu-dot_r
        desired_force         m     F_d: F(s) on ``force_row``, ``moments`` on the other force rows, 0 elsewhere
        path_position_error   k     e_p = E_p(x) (P (c - c_r), rotation error) (the controller's input)
        reference_position    3     c_d, the reference point on C = 0 (world, m)
        reference_normal      3     the surface's outward normal there
        path_error            3     c - c_d (world, m): the pad centre from its reference point
        path_progress         3     [segment index, arc length s (m), t_path (s)]
        path_done             1     1 once the path has ended, else 0
        ====================  ====  ==========================================================

        Args:
            plant, end_effector_frame, end_effector_point: as for HybridController (the controller's
                plant, finalized; the point is the pad centre, 3 finite numbers in the frame, m).
            constraint_space: the controller's ConstraintSpace on a PoseChart (its E_p gives the rows).
            path: a core.paths.SurfacePath.
            heading: the world direction the tool's x axis keeps, turned into the tangent plane (3 finite
                numbers, not along the path's first normal).
            force_row: the row of C whose force is the normal force (an integer, 0 for the surface
                constraints; not a kinematic row).
            dwell: s between the start (or the first contact) and the path's start (finite, >= 0).
            wait_for_contact: True or False: start the path's clock at the first CONTACT on ``contact_phase``.
            period: the control period (s, positive and finite) at which ``contact_phase`` is read (needed
                with wait_for_contact; else None or ignored).
            moments: the F_d of the force-controlled rows other than ``force_row`` (a flat tool's orientation
                rows: the moments about the controlled point, N m), one per such row, in row order; empty: zero.

        Every argument is checked here (``core.arguments``): a bad one is a one-line ArgumentError naming it.
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, constraint_space, path,
                       heading=(1.0, 0.0, 0.0), force_row=0, dwell=0.0, wait_for_contact=False, period=None,
                       moments=(), converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._arguments = (plant, end_effector_frame, end_effector_point, constraint_space, path, heading,
                               force_row, dwell, wait_for_contact, period, moments)
            owner = "PathSource"
            instance(plant, "plant", owner, MultibodyPlant, what="a MultibodyPlant (float, finalized)")
            if not plant.is_finalized():
                raise ArgumentError(f"{owner}: plant must be finalized (plant.Finalize())")
            end_effector_point = vector(end_effector_point, "end_effector_point", owner, 3, unit="m")
            instance(constraint_space, "constraint_space", owner, ConstraintSpace)
            chart = constraint_space.chart
            if not isinstance(chart, PoseChart):
                raise ArgumentError(f"{owner}: constraint_space must be on a PoseChart (a path over a surface turns "
                                    f"the tool through any direction, where Euler angles are singular), got its "
                                    f"{chart.name} chart")
            self.constraint_space, self.chart = constraint_space, chart
            self.path = instance(path, "path", owner, SurfacePath, what="a core.paths.SurfacePath")
            self.heading = vector(heading, "heading", owner, 3)
            k, m = constraint_space.velocity_size, constraint_space.force_size
            kinematic = list(constraint_space.constraint.kinematic_rows)
            self.force_row = number(force_row, "force_row", owner, low=0, high=m - 1, integer=True)
            if self.force_row in kinematic:
                raise ArgumentError(f"{owner}: force_row must be a force-controlled row of C (0..{m - 1}, not "
                                    f"kinematic {kinematic}), got {self.force_row}")
            self.moment_rows = [i for i in range(m) if i not in kinematic and i != self.force_row]
            moments = list(moments)
            if moments and len(moments) != len(self.moment_rows):
                raise ArgumentError(f"{owner}: moments must have one entry per force-controlled row besides force_row "
                                    f"(rows {self.moment_rows}; the orientation rows held: {kinematic}), got "
                                    f"{describe(moments)}")
            self.moments = (vector(moments, "moments", owner, len(moments), unit="N m") if moments
                            else np.zeros(len(self.moment_rows)))
            self.dwell = nonnegative(dwell, "dwell", owner, unit="s")
            reference_rotation(path.first_point()[1], self.heading, owner)        # the heading is usable
            self.wait_for_contact = boolean(wait_for_contact, "wait_for_contact", owner)
            period = positive(period, "period", owner, unit="s", allow_none=True)
            _, self.kinematics, self._state_port, plant_context = declare_task_input(
                self, T, plant, end_effector_frame, end_effector_point, chart)
            self._phase_port = None
            time_tickets = {self.time_ticket()}
            if self.wait_for_contact:
                if period is None:
                    raise ArgumentError(f"{owner}: wait_for_contact needs period (the control period, s), got None")
                self._phase_port = self.DeclareVectorInputPort("contact_phase", 1)
                self.DeclareDiscreteState(np.array([NOT_STARTED]))
                declare_periodic_update(self, float(period), tick_offset(period), self._update_start)
                time_tickets.add(self.xd_ticket())
            # The measured x, nu, E_p and E_p-dot once per state; the reference once per time (and start).
            self._task = declare_cached_value(self, "x, nu, E_p, E_p-dot", lambda context: self._calc_task(
                plant_context.Eval(context)), {plant_context.ticket()})
            self._reference = declare_cached_value(self, "the path's reference", self._calc_reference, time_tickets)
            both = {self._task.ticket(), self._reference.ticket()}
            for name, size, calc, prerequisites in (
                    ("desired_velocity", k, self._calc_velocity, both),
                    ("desired_acceleration", k, self._calc_acceleration, both),
                    ("desired_force", m, self._calc_force, {self._reference.ticket()}),
                    ("path_position_error", k, self._calc_position_error, both),
                    ("reference_position", 3, lambda c, o: o.SetFromVector(self._reference.Eval(c)["c"]),
                     {self._reference.ticket()}),
                    ("reference_normal", 3, lambda c, o: o.SetFromVector(self._reference.Eval(c)["n"]),
                     {self._reference.ticket()}),
                    ("path_error", 3, self._calc_path_error, both),
                    ("path_progress", 3, lambda c, o: o.SetFromVector(self._reference.Eval(c)["progress"]),
                     {self._reference.ticket()}),
                    ("path_done", 1, lambda c, o: o.SetFromVector([self._reference.Eval(c)["done"]]),
                     {self._reference.ticket()})):
                self.DeclareVectorOutputPort(name, size, calc, prerequisites_of_calc=prerequisites)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, *other._arguments, converter=converter)

        def get_contact_phase_input_port(self):
            """The ``contact_phase`` input (only with ``wait_for_contact``; else None)."""
            return self._phase_port

        def path_time(self, context):
            """t_path at ``context`` (negative before the path starts)."""
            start = self.dwell
            if self.wait_for_contact:
                start = float(value(context.get_discrete_state(0).CopyToVector())[0])
            return float(value(context.get_time())) - start

        def _update_start(self, context, discrete_state):
            start = float(value(context.get_discrete_state(0).CopyToVector())[0])
            phase = int(round(float(value(self._phase_port.Eval(context))[0])))
            if start >= NOT_STARTED and phase == int(ContactPhase.CONTACT):
                discrete_state.get_mutable_vector(0).SetFromVector([float(value(context.get_time())) + self.dwell])

        # -- the reference -------------------------------------------------------------------------
        def _calc_reference(self, context):
            """The path's reference at t_path (time only): the sample, R_d, omega_d, omega-dot_d, F_d."""
            t = self.path_time(context)
            sample = self.path.evaluate(t)
            try:
                R_d, omega_d, omega_dot = reference_frame(sample.normal, sample.normal_rate,
                                                          sample.normal_acceleration, self.heading)
            except ArgumentError as error:
                raise ArgumentError(f"{self.get_name() or 'PathSource'}: heading (path.heading) at arc length "
                                    f"{sample.arc_length:.4g} m (path time {t:.4g} s): "
                                    f"{str(error).split(': ', 1)[-1]}") from None
            force = np.zeros(self.constraint_space.force_size)
            force[self.force_row] = sample.force
            force[self.moment_rows] = self.moments
            return {"sample": sample, "R_d": R_d, "omega": omega_d, "omega_dot": omega_dot, "c": sample.position,
                    "n": sample.normal, "force": force, "done": 1.0 if t > self.path.duration else 0.0,
                    "progress": np.array([sample.segment, sample.arc_length, t])}

        def _calc_task(self, plant_context):
            """The measured x, nu, c, E_p, E_p-dot and the pad's depth delta = -C_1 / |grad C_1| with its rate."""
            task = self.kinematics.evaluate(plant_context)
            x, nu = task.configuration, task.velocity
            constraint, row = self.constraint_space.constraint, self.force_row
            gradient = constraint.force_projection(x)[row][:3]                 # grad_p C_1
            gradient_rate = constraint.force_projection_rate(x, nu)[row][:3]
            length = sqrt(gradient @ gradient)
            value, rate = constraint.value(x)[row], constraint.force_projection(x)[row] @ nu
            depth = -value / length
            depth_rate = -rate / length + value * (gradient @ gradient_rate) / (length * length * length)
            E_p, E_p_dot = self.constraint_space.velocity_projection.matrix_and_rate(x, nu)
            return x, nu, task.position, E_p, E_p_dot, depth, depth_rate

        def _at_depth(self, context):
            """(c_r, nu_r, nu-dot_r): the reference point following the pad at its depth (module docstring)."""
            _, _, _, _, _, depth, depth_rate = self._task.Eval(context)
            reference = self._reference.Eval(context)
            sample = reference["sample"]
            c_r = sample.position - depth * sample.normal
            velocity = sample.velocity - depth * sample.normal_rate
            acceleration = sample.acceleration - depth_rate * sample.normal_rate - depth * sample.normal_acceleration
            return (c_r, np.concatenate([velocity, reference["omega"]]),
                    np.concatenate([acceleration, reference["omega_dot"]]))

        # -- outputs ---------------------------------------------------------------------------------
        def _calc_velocity(self, context, output):
            E_p = self._task.Eval(context)[3]
            output.SetFromVector(E_p @ self._at_depth(context)[1])

        def _calc_acceleration(self, context, output):
            E_p, E_p_dot = self._task.Eval(context)[3:5]
            _, nu_r, nu_dot_r = self._at_depth(context)
            output.SetFromVector(E_p_dot @ nu_r + E_p @ nu_dot_r)

        def _calc_force(self, context, output):
            output.SetFromVector(self._reference.Eval(context)["force"])

        def _calc_position_error(self, context, output):
            x, _, c, E_p = self._task.Eval(context)[:4]
            reference = self._reference.Eval(context)
            n, displacement = reference["n"], c - self._at_depth(context)[0]
            R, R_d = np.asarray(x[3:]).reshape(3, 3), reference["R_d"]
            product = R @ R_d.T
            output.SetFromVector(E_p @ np.concatenate([displacement - (displacement @ n) * n,
                                                       0.5 * _vee(product - product.T)]))

        def _calc_path_error(self, context, output):
            output.SetFromVector(self._task.Eval(context)[2] - self._reference.Eval(context)["c"])

    return Impl


PathSource = default_instantiation(PathSource_)
