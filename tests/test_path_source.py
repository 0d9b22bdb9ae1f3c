"""The path's commands (systems.path_source.PathSource) on a real arm, the controller's
path_position_error input and the contact supervisor's lift-off: each checked against what it must
equal (the reference twist mapped by E_p, a derivative along the motion, central differences)."""

import numpy as np
import pytest

from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import ContactSupervisor, SupervisionConfig
from drake_hybrid.core.kinematics import EndEffectorKinematics, inverse_kinematics
from drake_hybrid.systems.path_source import PathSource, reference_frame
from drake_hybrid.tasks.builtin.robots import UR5E_SEED, add_ur5e_with_pad
from drake_hybrid.tasks.path import build_path
from drake_hybrid.tasks.registry import get_task


@pytest.fixture(scope="module")
def job():
    """The surface-polishing task's path on the sphere, the UR5e's plant and a PathSource on it."""
    task = get_task("surface-polishing")
    config = task.default_config()
    config.path.pattern.size = [0.04, 0.02]           # two short lines: fast to build
    plant = MultibodyPlant(0.0)
    robot = add_ur5e_with_pad(plant)
    plant.Finalize()
    space = task.constraint_space(config)
    path = build_path(task, config)
    heading = np.array([1.0, 0.0, 0.0])
    dut = PathSource(plant, robot.end_effector_frame, robot.end_effector_point, space, path, heading=heading,
                     dwell=0.1)
    return dict(task=task, config=config, plant=plant, robot=robot, space=space, path=path, dut=dut, heading=heading)


def state_on_reference(job, t, offset=np.zeros(3)):
    """[q; v] with the pad centre at the reference at path time t (shifted by ``offset``), in the
    reference frame, moving with the reference twist."""
    plant, dut = job["plant"], job["dut"]
    sample = job["path"].evaluate(t)
    R, omega, _ = reference_frame(sample.normal, sample.normal_rate, sample.normal_acceleration, job["heading"])
    context = plant.CreateDefaultContext()
    kinematics = EndEffectorKinematics(plant, plant.GetFrameByName("pad_center"), np.zeros(3),
                                       job["space"].chart)
    q = inverse_kinematics(kinematics, context, RigidTransform(RotationMatrix(R), sample.position + offset),
                           UR5E_SEED)
    plant.SetPositions(context, q)
    J = kinematics.evaluate(context).spatial_jacobian                 # [omega; v] = J v
    v = np.linalg.solve(J, np.concatenate([omega, sample.velocity]))
    return np.concatenate([q, v]), sample


def evaluate(dut, state, time):
    context = dut.CreateDefaultContext()
    context.SetTime(time)
    dut.get_input_port(0).FixValue(context, state)
    return {name: dut.GetOutputPort(name).Eval(context).copy() for name in
            ("desired_velocity", "desired_acceleration", "desired_force", "path_position_error", "path_error",
             "reference_position", "path_progress", "path_done")}


def test_on_the_reference_the_command_is_the_measured_velocity_and_the_errors_vanish(job):
    dut, space = job["dut"], job["space"]
    for t_path in (0.3, 1.0, job["path"].duration - 0.2):
        state, sample = state_on_reference(job, t_path)
        out = evaluate(dut, state, t_path + 0.1)                          # dwell 0.1 s
        plant_context = job["plant"].CreateDefaultContext()
        job["plant"].SetPositionsAndVelocities(plant_context, state)
        task = dut.kinematics.evaluate(plant_context)
        E_p = space.velocity_projection.matrix(task.configuration)
        # e_p' = 0 and e_p = 0, to the spline's distance from the exact offset sphere (< 1e-6 m; times its turn).
        np.testing.assert_allclose(out["desired_velocity"], E_p @ task.velocity, atol=1e-8)
        np.testing.assert_allclose(out["path_position_error"], 0.0, atol=1e-7)
        np.testing.assert_allclose(out["path_error"], 0.0, atol=1e-9)
        np.testing.assert_allclose(out["desired_force"], [sample.force, 0.0, 0.0])
        assert out["path_progress"][2] == pytest.approx(t_path) and out["path_done"][0] == 0.0
    assert evaluate(dut, state, job["path"].duration + 0.2)["path_done"][0] == 1.0


def test_the_desired_acceleration_is_the_derivative_of_the_command_along_the_motion(job):
    """r-ddot_pd = d/dt r-dot_pd along (t, q + t q-dot): central differences, off the reference too."""
    dut, h = job["dut"], 1e-6
    for t_path in (0.4, 1.3):
        state, _ = state_on_reference(job, t_path, offset=np.array([0.001, -0.002, 0.0005]))
        n = len(state) // 2
        state[n:] += 0.05                                              # not the reference's twist
        q, v = state[:n], state[n:]
        plus = evaluate(dut, np.concatenate([q + h * v, v]), t_path + 0.1 + h)["desired_velocity"]
        minus = evaluate(dut, np.concatenate([q - h * v, v]), t_path + 0.1 - h)["desired_velocity"]
        np.testing.assert_allclose(evaluate(dut, state, t_path + 0.1)["desired_acceleration"],
                                   (plus - minus) / (2 * h), atol=1e-6)


def test_the_position_error_is_the_displacement_along_the_surface_in_the_view_rows(job):
    """Moved by d along the surface and by s along the normal (a pressed pad), the view rows read the
    tangent part of d (u . d, v . d) and nothing of s: the reference follows the pad at its depth
    (to first order: the sphere's curvature leaves |d|^2 / rho)."""
    dut = job["dut"]
    _, sample = state_on_reference(job, 0.6)
    n = sample.normal
    tangent = np.cross(n, [0.0, 1.0, 0.0])
    tangent /= np.linalg.norm(tangent)
    for move in (0.002 * tangent, -0.001 * n, 0.002 * tangent - 0.0008 * n):
        state, _ = state_on_reference(job, 0.6, offset=move)
        error = evaluate(dut, state, 0.7)["path_position_error"]
        along = move - (move @ n) * n
        np.testing.assert_allclose(error, [0.0, along[0], along[1]], atol=(move @ move) / 0.17)


@pytest.mark.parametrize("output", ["path_position_error", "desired_velocity", "desired_acceleration"])
def test_the_autodiff_source_differentiates_its_commands_as_central_differences(job, output):
    dut = job["dut"]
    ad = dut.ToAutoDiffXd()
    state, _ = state_on_reference(job, 0.8, offset=np.array([0.001, 0.0, -0.0005]))
    state[len(state) // 2:] += 0.03
    context = ad.CreateDefaultContext()
    context.SetTime(0.9)
    ad.get_input_port(0).FixValue(context, InitializeAutoDiff(state))
    gradient = ExtractGradient(ad.GetOutputPort(output).Eval(context))
    h = 1e-6
    for k in range(len(state)):
        step = np.zeros(len(state))
        step[k] = h
        difference = (evaluate(dut, state + step, 0.9)[output] - evaluate(dut, state - step, 0.9)[output]) / (2 * h)
        np.testing.assert_allclose(gradient[:, k], difference, atol=1e-6 * max(1.0, np.max(np.abs(difference))),
                                   err_msg=f"state {k}")


def test_the_controller_takes_its_position_error_from_the_path_input(job):
    plant, robot, space = job["plant"], job["robot"], job["space"]
    gains = HybridGains(velocity=[30.0], position=[200.0], force_proportional=[0.5, 0, 0], force_integral=[15.0, 1, 1],
                        constraint_frequency=15.0)
    dut = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains=gains,
                           mode="position-force", path_position_error=True, fast_law=False)
    assert dut.get_path_position_error_input_port().size() == 3
    state, _ = state_on_reference(job, 0.5)
    context = dut.CreateDefaultContext()
    dut.get_estimated_state_input_port().FixValue(context, state)
    dut.get_measured_wrench_input_port().FixValue(context, np.zeros(6))
    for name, value in (("desired_velocity", np.zeros(3)), ("desired_acceleration", np.zeros(3)),
                        ("desired_force", [10.0, 0, 0])):
        dut.GetInputPort(name).FixValue(context, value)
    torques = []
    for error in ([0.0, 0.0, 0.0], [0.0, 0.001, 0.0]):
        dut.get_path_position_error_input_port().FixValue(context, error)
        np.testing.assert_allclose(dut.GetOutputPort("position_error").Eval(context), error)
        torques.append(dut.GetOutputPort("actuation").Eval(context).copy())
    assert np.linalg.norm(torques[1] - torques[0]) > 0                 # -K_p e_p acts
    # Without the option the input does not exist and e_p is the integral (zero here).
    plain = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains=gains,
                             mode="position-force", fast_law=False)
    assert plain.get_path_position_error_input_port() is None


def test_the_supervisor_lifts_off_at_the_end_and_does_not_touch_down_again():
    dut = ContactSupervisor(SupervisionConfig(approach_speed=0.02, lift_height=0.01), 1, (), 1e-3,
                            ContactPhase.CONTACT, lift_off=True)
    state = np.array([float(ContactPhase.CONTACT), 0.0, 1.0, -0.001, -0.001, 0.0])
    pressing = lambda s, lift, C=-0.001: dut.next_state(s, np.array([10.0]), np.array([10.0]), np.array([C]), True,
                                                       lift)
    assert pressing(state, False)[0] == ContactPhase.CONTACT
    lifted = pressing(state, True)
    assert lifted[0] == ContactPhase.HOLD and lifted[5] == 1.0 and lifted[4] == -0.001    # C_r = C there
    for step in range(1, 700):
        lifted = pressing(lifted, False)                                  # still pressing: no re-contact
        assert lifted[0] == ContactPhase.HOLD
        # C_r moves away (F_d = +10 pushes up: the pressing direction is -1 in C) at 0.02 m/s, up to 10 mm.
        assert lifted[4] == pytest.approx(-0.001 + min(0.02e-3 * step, 0.01))
    context = dut.CreateDefaultContext()
    dut.set_initial_state(context, ContactPhase.CONTACT, [0.0])
    assert dut.GetOutputPort("lifting").Eval(context)[0] == 0.0
    with pytest.raises(ValueError, match=r"supervision\.lift_height must be positive"):
        SupervisionConfig(lift_height=0.0).validate()
