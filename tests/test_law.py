"""The law's lines (drake_hybrid/control/law.py), each against its equation, float and AutoDiffXd."""

import numpy as np
import pytest

from pydrake.autodiffutils import AutoDiffXd, ExtractGradient

from drake_hybrid.control.gains import ControlMode, HybridGains
from drake_hybrid.control.law import (force_command, force_error, force_row_damping, guarded_acceleration,
                                      held_row_acceleration, held_row_compensation, impedance_compensation,
                                      impedance_gain, integral_rates, motion_acceleration, tangential_compensation,
                                      velocity_error)
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.core.linalg import value


def _seeded(values):
    """AutoDiffXd copies of ``values``, each seeded with its own unit derivative."""
    size = len(values)
    return np.array([AutoDiffXd(v, np.eye(size)[i]) for i, v in enumerate(values)], dtype=object)


@pytest.fixture
def gains():
    return HybridGains(velocity=[3.0, 5.0], position=[4.0], force_proportional=[0.5], force_integral=[20.0],
                       constraint_frequency=7.0).matrices(2, 2, ControlMode.POSITION_FORCE)


def test_motion_acceleration_is_3_1_12_and_remark_3(gains):
    desired, error, position = np.array([1.0, -2.0]), np.array([0.3, 0.1]), np.array([0.05, -0.2])
    velocity_mode = motion_acceleration(desired, gains, error, position, ControlMode.VELOCITY_FORCE)
    np.testing.assert_allclose(velocity_mode, desired - gains.velocity @ error, rtol=0, atol=1e-15)
    position_mode = motion_acceleration(desired, gains, error, position, ControlMode.POSITION_FORCE)
    np.testing.assert_allclose(position_mode, velocity_mode - gains.position @ position, rtol=0, atol=1e-15)
    # Its derivative with respect to e_p' is -K_v, in AutoDiffXd (the same function).
    derivative = ExtractGradient(motion_acceleration(desired, gains, _seeded(error), position,
                                                     ControlMode.VELOCITY_FORCE))
    np.testing.assert_allclose(derivative, -gains.velocity, rtol=0, atol=1e-15)


def test_force_command_and_its_integral_gain(gains):
    desired, error, integral = np.array([-10.0, 0.0]), np.array([0.5, 0.0]), np.array([0.01, 0.0])
    mask = np.array([1.0, 0.0])                                   # row 1 kinematic
    command = force_command(desired, gains, error, integral, mask, in_contact=True)
    np.testing.assert_allclose(command, -desired + gains.force_proportional @ error
                               + gains.force_integral @ integral, rtol=0, atol=1e-15)
    # Off the surface only the kinematic rows keep their feedforward.
    np.testing.assert_array_equal(force_command(desired, gains, error, integral, mask, in_contact=False),
                                  command * (1.0 - mask))
    derivative = ExtractGradient(force_command(desired, gains, error, _seeded(integral), mask, True))
    np.testing.assert_allclose(derivative, gains.force_integral, rtol=0, atol=1e-15)


def test_force_row_damping_acts_on_the_force_rows_in_contact_only():
    gains = HybridGains(force_proportional=[0.5], force_integral=[20.0],
                        force_damping=[[30.0, 5.0], [5.0, 10.0]]).matrices(2, 2, ControlMode.VELOCITY_FORCE)
    rate, mask = np.array([0.02, -0.01]), np.array([1.0, 0.0])             # row 1 kinematic
    np.testing.assert_allclose(force_row_damping(rate, gains.force_damping, mask, in_contact=True),
                               -(gains.force_damping @ rate) * mask, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(force_row_damping(rate, gains.force_damping, mask, in_contact=False), [0.0, 0.0])
    derivative = ExtractGradient(force_row_damping(_seeded(rate), gains.force_damping, np.ones(2), True))
    np.testing.assert_allclose(derivative, -gains.force_damping, rtol=0, atol=1e-15)
    default = HybridGains().matrices(1, 1, ControlMode.VELOCITY_FORCE)      # the paper's a_f = 0
    np.testing.assert_array_equal(default.force_damping, [[0.0]])


def test_errors_and_integral_rates():
    E_p = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    projected, error = velocity_error(E_p, np.array([0.2, -0.1, 0.4]), np.array([0.1, 0.4]))
    np.testing.assert_allclose(projected, [0.2, 0.4])
    np.testing.assert_allclose(error, [0.1, 0.0])
    e_f = force_error(np.array([-9.0, 3.0]), np.array([-10.0, 0.0]), np.array([1.0, 0.0]))
    np.testing.assert_allclose(e_f, [1.0, 0.0])                   # no force loop on a kinematic row
    assert [list(r) for r in integral_rates(error, e_f, frozen=False, in_contact=True)] == [[1.0, 0.0], list(error)]
    assert [list(r) for r in integral_rates(error, e_f, frozen=False, in_contact=False)] == [[0.0, 0.0], list(error)]
    assert [list(r) for r in integral_rates(error, e_f, frozen=True, in_contact=True)] == [[0.0, 0.0], [0.0, 0.0]]


def test_held_rows_have_the_designed_poles():
    """a_f = -3 w_c C-dot - 2 w_c^2 C: the row's closed loop C-ddot = a_f has poles -w_c and -2 w_c."""
    w_c, mask = 7.0, np.array([1.0, 0.0])
    # A = [[0, 1], [d a_f/d C, d a_f/d C-dot]] on row 1 (kinematic), from the AutoDiffXd derivative.
    state = _seeded([0.01, -0.02])                                  # (C, C-dot) of row 1
    a_f = held_row_acceleration(np.array([0.0, state[0]], dtype=object), np.array([0.0, state[1]], dtype=object),
                                w_c, mask)
    assert value(a_f)[0] == 0.0                       # nothing on a force-controlled row
    gradient = ExtractGradient(a_f[1:])[0]
    A = np.array([[0.0, 1.0], gradient])
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(A).real), [-2 * w_c, -w_c], rtol=1e-12)


def test_the_compensations_cancel_the_forces_the_paper_assumes_zero():
    """F_c = -F_v on the velocity rows and F_h = -F on the held rows, in velocity-force and
    position-force mode with the option on; none in impedance mode (K_0 takes them), with the option
    off, or (F_h) on a rejected wrench. Their derivative is -I on the rows they cancel, in AutoDiffXd."""
    mask = np.array([1.0, 0.0, 0.0])                               # rows 1 and 2 held
    tangential, force = np.array([0.3, -0.2]), np.array([-10.0, 0.04, -0.01])
    for mode in (ControlMode.VELOCITY_FORCE, ControlMode.POSITION_FORCE):
        np.testing.assert_array_equal(tangential_compensation(tangential, mode, True), -tangential)
        np.testing.assert_array_equal(held_row_compensation(force, mask, True, mode, True), [0.0, -0.04, 0.01])
        assert tangential_compensation(tangential, mode, False) is None
        assert held_row_compensation(force, mask, True, mode, False) is None
        assert held_row_compensation(force, mask, False, mode, True) is None      # dropout: F = F_d, not measured
    assert tangential_compensation(tangential, ControlMode.IMPEDANCE_FORCE, True) is None
    assert held_row_compensation(force, mask, True, ControlMode.IMPEDANCE_FORCE, True) is None
    derivative = ExtractGradient(held_row_compensation(_seeded(force), mask, True, ControlMode.VELOCITY_FORCE, True))
    np.testing.assert_allclose(derivative, -np.diag(1.0 - mask), rtol=0, atol=0)


def test_guarded_move_approaches_along_the_pressing_direction():
    mask = np.array([1.0, 0.0])
    desired_force = np.array([-10.0, 5.0])                         # F on the robot: it pushes along +C
    at_rest, C, C_r = np.zeros(2), np.array([0.002, 0.5]), np.array([0.003, -0.5])
    approach = guarded_acceleration(C, at_rest, C, desired_force, mask, ContactPhase.APPROACH, 0.02, 30.0)
    np.testing.assert_allclose(approach, [2 * 30.0 * 0.02, 0.0])    # -2 K_a (0 - s n_C), n_C = +1, row 1 held
    # Behind the reference by 1 mm: - K_a^2 (C - C_r) adds 900 * 0.001 (integral action).
    behind = guarded_acceleration(C, at_rest, C_r, desired_force, mask, ContactPhase.APPROACH, 0.02, 30.0)
    np.testing.assert_allclose(behind, [2 * 30.0 * 0.02 + 900.0 * 0.001, 0.0])
    hold = guarded_acceleration(C, np.array([0.1, 0.0]), C, desired_force, mask, ContactPhase.HOLD, 0.02, 30.0)
    np.testing.assert_allclose(hold, [-6.0, 0.0])                  # s = 0 in HOLD: brake C-dot


def test_impedance_compensation_splits_k0_over_motion_rows(rng):
    class Values:
        velocity_projection = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        force_projection = np.array([[0.0, 0.0, 1.0]])
    A = rng.standard_normal((3, 3))
    mobility = A @ A.T + 3 * np.eye(3)
    F_v, F = np.array([0.4, -0.3]), np.array([-10.0])
    on_velocity, on_force = impedance_compensation(Values, mobility, F_v, F, ())
    K_0 = impedance_gain(Values.velocity_projection, Values.force_projection, mobility)
    np.testing.assert_allclose(on_velocity, K_0 @ F_v, rtol=1e-14)
    np.testing.assert_array_equal(on_force, [0.0])
    # With the force row kinematic it is a motion row: K_0 is 3x3 and acts on [F_v; F].
    on_velocity, on_force = impedance_compensation(Values, mobility, F_v, F, (0,))
    K_0 = impedance_gain(Values.velocity_projection, Values.force_projection, mobility, [0])
    full = K_0 @ np.concatenate([F_v, F])
    np.testing.assert_allclose(np.concatenate([on_velocity, on_force]), full, rtol=1e-14)


def test_a_lagged_wrench_is_split_where_it_was_measured():
    """law.measured_forces: on a sphere of radius rho the frictionless contact force turns with the
    pad. A wrench T late, split with the current E(x), reads as a tangential force of about
    F T |v| / rho (over the row's cosine); split where it was measured (wrench_lag = T) it is F_v = 0 to O(T^2)."""
    import sympy

    from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
    from drake_hybrid.control.law import measured_forces

    rho, pressing, lag, speed = 0.07, 10.0, 1e-3, 0.02
    chart = PoseChart()
    constraint = surface_constraint(chart, lambda p: sympy.sqrt(p[0]**2 + p[1]**2 + p[2]**2) - rho,
                                    name="sphere", normal_rows=False)
    space = ConstraintSpace(constraint, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0)))
    p = rho * np.array([np.sin(0.3), 0.0, np.cos(0.3)])
    v = speed * np.array([np.cos(0.3), 0.0, -np.sin(0.3)])              # tangent: C-dot = 0
    x, nu = chart.configuration(np.diag([1.0, -1.0, -1.0]), p), np.concatenate([v, np.zeros(3)])  # tool down
    values = space.evaluate(x, nu)
    earlier = p - lag * v
    wrench = np.concatenate([np.zeros(3), pressing * earlier / np.linalg.norm(earlier)])   # [n; f] on the pad
    E_f_dot = constraint.force_projection_rate(x, nu)
    late, force_late, _ = measured_forces(space, values, x, wrench, np.array([-pressing]))
    split, force, valid = measured_forces(space, values, x, wrench, np.array([-pressing]), lag, E_f_dot)
    assert valid
    # the x row of E_p against the normal tilted by 0.3 rad: F T |v| / (rho cos 0.3)
    assert np.linalg.norm(late) == pytest.approx(pressing * lag * speed / (rho * np.cos(0.3)), rel=0.01)
    assert np.linalg.norm(split) < 1e-3 * np.linalg.norm(late)
    assert abs(abs(force[0]) - pressing) < 1e-6 < abs(abs(force_late[0]) - pressing)   # F too, through E's skew
