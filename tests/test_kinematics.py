"""Analytic Jacobian J and J-dot q-dot in chart coordinates, from Drake, against finite differences."""

import numpy as np
import pytest

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid import EndEffectorKinematics, EulerZXZChart, PlanarChart, PoseChart
from drake_hybrid.core.linalg import value

EPS = 1e-6
POINT = np.array([0.03, -0.02, 0.12])


def kinematics_at(kinematics, context, q, v):
    kinematics.plant.SetPositions(context, q)
    kinematics.plant.SetVelocities(context, v)
    return kinematics.evaluate(context)


def random_state(rng, n, chart, kinematics, context):
    """A random state at which the Euler chart is regular and angles are away from +-pi."""
    for _ in range(100):
        q, v = rng.uniform(-1.5, 1.5, n), rng.normal(size=n)
        try:
            x = kinematics_at(kinematics, context, q, v).configuration
        except ValueError:
            continue
        if isinstance(chart, EulerZXZChart) and (np.abs(np.abs(x[[3, 5]]) - np.pi).min() < 0.2):
            continue
        return q, v
    raise RuntimeError("no regular state found")


@pytest.mark.parametrize("chart", [EulerZXZChart(), PoseChart()], ids=lambda c: c.name)
def test_spatial_jacobian_and_bias_match_finite_differences(chart, six_dof_arm, rng):
    plant, frame = six_dof_arm
    kinematics = EndEffectorKinematics(plant, frame, POINT, chart)
    context = plant.CreateDefaultContext()
    for _ in range(5):
        q, v = random_state(rng, 6, chart, kinematics, context)
        k = kinematics_at(kinematics, context, q, v)
        if isinstance(chart, EulerZXZChart):
            # J = dr/dq: central differences of the chart coordinates.
            J_fd = np.column_stack([
                (kinematics_at(kinematics, context, q + EPS * e, v).configuration
                 - kinematics_at(kinematics, context, q - EPS * e, v).configuration) / (2 * EPS)
                for e in np.eye(6)])
            np.testing.assert_allclose(k.jacobian, J_fd, atol=1e-7)
        # nu = J q-dot, and J-dot q-dot = d/dt (J(q + t v) v) at t = 0.
        np.testing.assert_allclose(k.velocity, k.jacobian @ v, atol=1e-12)
        J_plus = kinematics_at(kinematics, context, q + EPS * v, v).jacobian
        J_minus = kinematics_at(kinematics, context, q - EPS * v, v).jacobian
        np.testing.assert_allclose(k.bias, (J_plus - J_minus) @ v / (2 * EPS), atol=1e-6)


def test_planar_jacobian_and_bias_match_finite_differences(planar_arm, rng):
    plant, frame, point = planar_arm
    chart = PlanarChart()
    kinematics = EndEffectorKinematics(plant, frame, point, chart)
    context = plant.CreateDefaultContext()
    for _ in range(5):
        q, v = rng.uniform(-1.0, 1.0, 3), rng.normal(size=3)
        k = kinematics_at(kinematics, context, q, v)
        lengths, angles = [1.0, 0.8, 0.3], np.cumsum(q)
        expected = [sum(l * np.cos(a) for l, a in zip(lengths, angles)),
                    sum(l * np.sin(a) for l, a in zip(lengths, angles)), angles[-1]]
        np.testing.assert_allclose(k.configuration, expected, atol=1e-14)       # theta = q1 + q2 + q3
        J_fd = np.column_stack([
            (kinematics_at(kinematics, context, q + EPS * e, v).configuration
             - kinematics_at(kinematics, context, q - EPS * e, v).configuration) / (2 * EPS) for e in np.eye(3)])
        np.testing.assert_allclose(k.jacobian, J_fd, atol=1e-8)
        J_plus = kinematics_at(kinematics, context, q + EPS * v, v).jacobian
        J_minus = kinematics_at(kinematics, context, q - EPS * v, v).jacobian
        np.testing.assert_allclose(k.bias, (J_plus - J_minus) @ v / (2 * EPS), atol=1e-6)


@pytest.mark.parametrize("chart", [EulerZXZChart(), PoseChart()], ids=lambda c: c.name)
def test_autodiff_kinematics_equal_float(chart, six_dof_arm, rng):
    plant, frame = six_dof_arm
    kinematics = EndEffectorKinematics(plant, frame, POINT, chart)
    context = plant.CreateDefaultContext()
    q, v = random_state(rng, 6, chart, kinematics, context)
    expected = kinematics_at(kinematics, context, q, v)
    plant_ad = plant.ToAutoDiffXd()
    kinematics_ad = kinematics.for_plant(plant_ad)
    context_ad = plant_ad.CreateDefaultContext()
    plant_ad.SetPositions(context_ad, [AutoDiffXd(qi, np.eye(12)[i]) for i, qi in enumerate(q)])
    plant_ad.SetVelocities(context_ad, [AutoDiffXd(vi, np.eye(12)[6 + i]) for i, vi in enumerate(v)])
    got = kinematics_ad.evaluate(context_ad)
    for name in ("configuration", "velocity", "jacobian", "bias"):
        assert getattr(got, name).dtype == object
        np.testing.assert_allclose(value(getattr(got, name)), getattr(expected, name), atol=1e-12, err_msg=name)
    # The derivative of x with respect to q is J: AutoDiffXd carries the analytic Jacobian.
    if isinstance(chart, EulerZXZChart):
        dx_dq = np.array([xi.derivatives()[:6] for xi in got.configuration])
        np.testing.assert_allclose(dx_dq, expected.jacobian, atol=1e-12)


def test_bad_frame_and_point(six_dof_arm):
    plant, _ = six_dof_arm
    with pytest.raises(ValueError, match="frame 'tool0' is not in the plant; its frames are"):
        EndEffectorKinematics(plant, "tool0", POINT, PoseChart())
    with pytest.raises(ValueError, match=r"point_in_frame must be a vector of 3 finite numbers \(m\)"):
        EndEffectorKinematics(plant, "link6", [0.0, 0.1], PoseChart())
    other, other_frame = __import__("conftest").make_serial_arm([[0, 0, 1]], [[0, 0, 0]])
    # A frame of another plant that has one of that name (e.g. the simulation's plant given for the
    # controller's): the message says to pass the name.
    with pytest.raises(ValueError, match="frame 'joint1_parent' is a Frame of another plant, not of this one"):
        EndEffectorKinematics(plant, other.GetFrameByName("joint1_parent"), POINT, PoseChart())
    with pytest.raises(ValueError, match=r"frame 'world' is a Frame of another plant, not of this one \(the plant "
                                         "has a frame of that name: pass the name"):
        EndEffectorKinematics(plant, other.world_frame(), POINT, PoseChart())
