"""Joint damping declared in the model on a discrete (SAP) plant (control.damping).

Two models: the planar 3R arm with a heavily damped wrist, and the xArm7 of example-robot-data
with the damping of its URDF as shipped (its last joint: b h / M = 11.8 at 1 ms).

The window task's planar 3R arm with a damped wrist, b = 300 N m s/rad on joint3 (its inertia at
the start is M_33 = 0.031 kg m^2, so b h / M = 9.7 at the 1 ms step; effort limits raised so that
the damping torque is not clipped). SAP damps at the end-of-step velocity: without compensating
that, the law's joint accelerations shrink by about 1 + b h / M and the velocity rows stall; with
it they track as the undamped arm does.
"""

import importlib.metadata
import warnings
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

from pydrake.geometry import HalfSpace
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.control import fast_compile
from drake_hybrid.control import law as law_module
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.damping import (JointDampingWarning, damped_joints, damping_compensation, joint_damping,
                                          warn_damped_joints)
from drake_hybrid.control.fast_law import FastLaw
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.law import impedance_blocks, impedance_gain
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.station.arm import add_actuators, mount_tool, urdf_effort_limits
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.tasks.builtin.window_washing import WindowWashing
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.registry import register_task

WRIST_DAMPING = 300.0           # N m s/rad


class DampedWristWindow(WindowWashing):
    """The window task with the wrist's damping declared in the model (both plants see it)."""

    name = "test-damped-wrist-window"

    def add_robot(self, plant, config):
        robot = super().add_robot(plant, config)
        plant.GetJointByName("joint3").set_default_damping(WRIST_DAMPING)
        for index in plant.GetJointActuatorIndices():
            plant.get_mutable_joint_actuator(index).set_effort_limit(1e4)
        return robot


@pytest.fixture(scope="module")
def damped_task():
    return register_task(DampedWristWindow())


def window_arm(damping=0.0):
    plant = MultibodyPlant(0.0)
    robot = WindowWashing().add_robot(plant, WindowWashing().default_config())
    plant.GetJointByName("joint3").set_default_damping(damping)
    plant.Finalize()
    return plant, robot


def test_the_compensation_is_h_b_times_the_commanded_acceleration():
    damping = np.array([0.0, 2.0, 10.0])
    acceleration = np.array([1.0, -3.0, 0.5])
    np.testing.assert_allclose(damping_compensation(damping, acceleration, 1e-3), [0.0, -6e-3, 5e-3])
    np.testing.assert_array_equal(damping_compensation(damping, acceleration, 0.0), np.zeros(3))   # continuous


def test_the_step_with_compensation_is_the_designed_one():
    """(M + h B)(v+ - v) = h (M a* + h B a*) gives v+ = v + h a*; without the term, (M + h B)^-1 M a*."""
    rng = np.random.default_rng(3)
    L = rng.normal(size=(3, 3))
    M = L @ L.T + 0.01 * np.eye(3)
    B, h, a = np.diag([0.0, 1.0, 300.0]), 1e-3, rng.normal(size=3)
    step = np.linalg.solve(M + h * B, h * (M @ a + damping_compensation(np.diag(B), a, h)))
    np.testing.assert_allclose(step, h * a, rtol=1e-12)
    uncompensated = np.linalg.solve(M + h * B, h * M @ a)
    assert np.linalg.norm(uncompensated - h * a) > 0.1 * np.linalg.norm(h * a)


def test_a_damping_dominated_joint_is_named_with_its_b_h_over_m():
    plant, _ = window_arm(WRIST_DAMPING)
    assert joint_damping(plant).tolist() == [0.0, 0.0, WRIST_DAMPING]
    found = damped_joints(plant, 1e-3)
    assert [name for name, _ in found] == ["joint3"]
    M_33 = plant.CalcMassMatrix(plant.CreateDefaultContext())[2, 2]
    assert found[0][1] == pytest.approx(WRIST_DAMPING * 1e-3 / M_33)
    with pytest.warns(JointDampingWarning, match=r"joint 'joint3': damping b h / M = \d") as record:
        warn_damped_joints(plant, 1e-3)
    assert len(record) == 1 and "\n" not in str(record[0].message)
    assert damped_joints(plant, 0.0) == []                        # continuous plant: nothing to warn
    assert damped_joints(plant, 1e-5) == []                       # b h / M = 0.1 at 10 us
    undamped, _ = window_arm(0.0)
    assert damped_joints(undamped, 1e-3) == []


def run(task, compensate, monkeypatch):
    if not compensate:
        # The law without the line: the generic law (the compiled one has the line too) with it zeroed.
        monkeypatch.setattr(FastLaw, "build", classmethod(lambda cls, controller, law, space: None))
        monkeypatch.setattr(law_module, "damping_compensation",
                            lambda damping, acceleration, step: 0.0 * acceleration)
    config = task.default_config()
    config.duration = 0.8                                          # 5 design time constants = 0.625 s
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = simulate(config, progress=False)
    damping_warnings = [w for w in caught if issubclass(w.category, JointDampingWarning)]
    return result.summary, damping_warnings


def test_the_damped_wrist_tracks_with_the_compensation(damped_task, monkeypatch):
    summary, damping_warnings = run(damped_task, True, monkeypatch)
    # Measured 0.187 % (the undamped arm: 0.187 %); target 2 %.
    assert summary.max_velocity_error_percent_after_5_time_constants < 2.0
    assert summary.max_force_error_percent_after_5_time_constants < 2.0
    assert len(damping_warnings) == 1 and "joint3" in str(damping_warnings[0].message)


def test_the_damped_wrist_stalls_without_it(damped_task, monkeypatch):
    summary, _ = run(damped_task, False, monkeypatch)
    # The theta row (commanded 0) lags by about 0.08 rad/s (loop slowed by about 1 + b h / M = 10.7;
    # 81.5 % of the 0.1 m/s speed as a norm over both rows); compensated it stays below 1e-3 rad/s.
    theta = summary.velocity_rows[1]
    assert theta.units == "rad/s" and theta.max_error_after_5_time_constants > 0.04


# -- a 7-DOF arm from a PyPI model package, its URDF damping as shipped ---------------------------

SHARE = Path(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
XARM7 = SHARE / "robots/xarm_description/urdf/xarm7.urdf"
TABLE = 0.15                                   # m, the plane the pad presses


@pytest.fixture(scope="module")
def xarm_table_task(tmp_path_factory):
    """The xArm7 (damping 10, 10, 5, 5, 5, ... N m s/rad in its URDF) pressing 10 N on a plane and
    spinning its pad. Its STL collision meshes (which Drake rejects) are dropped: only the pad
    touches anything."""
    tree = ElementTree.parse(XARM7)
    for link in tree.getroot().iter("link"):
        for collision in link.findall("collision"):
            link.remove(collision)
    urdf = tmp_path_factory.mktemp("xarm7") / "xarm7_without_collision.urdf"
    tree.write(urdf)

    def add_xarm(plant):
        parser = Parser(plant)
        parser.package_map().Add("example-robot-data", str(SHARE))
        arm = parser.AddModels(str(urdf))[0]                       # welded to the world by the URDF
        add_actuators(plant, arm, urdf_effort_limits(XARM7))
        return mount_tool(plant, arm, "link_eef")

    def add_table(plant):
        return add_rigid_workpiece(plant, HalfSpace(), RigidTransform([0.0, 0.0, TABLE]), name="table")

    chart = PoseChart()
    plane = surface_constraint(chart, lambda p: p[2] - (TABLE + 0.02), name="table", normal_rows=False)
    space = ConstraintSpace(plane, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0), name="rest"))
    start = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0.4, 0.0, TABLE + 0.02])
    return register_task(CustomTask("test-xarm7-table", add_robot=add_xarm, add_workpiece=add_table,
                                    constraint_space=space, start_pose=start,
                                    joint_guess=[0.0, 0.2, 0.0, 1.0, 0.0, 0.8, 0.0]))


def spin_run(task, compensate, monkeypatch):
    if not compensate:
        # The law without the line: the generic law (the compiled one has the line too) with it zeroed.
        monkeypatch.setattr(FastLaw, "build", classmethod(lambda cls, controller, law, space: None))
        monkeypatch.setattr(law_module, "damping_compensation",
                            lambda damping, acceleration, step: 0.0 * acceleration)
    config = task.default_config(desired_velocity=[0.02, 0.0, 0.0, 0.0, 0.5], desired_force=[10.0],
                                 mode="velocity-force", duration=0.6,            # 5 time constants: 0.5 s
                                 gains=HybridGains(velocity=[10.0], force_proportional=[0.5], force_integral=[15.0]))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = simulate(config, progress=False)
    return result, [w for w in caught if issubclass(w.category, JointDampingWarning)]


def test_the_xarm7_spin_row_tracks_with_its_urdf_damping_compensated(xarm_table_task, monkeypatch):
    result, damping_warnings = spin_run(xarm_table_task, True, monkeypatch)
    summary = result.summary
    # Measured 0.657 % (the spin row, 3.3e-3 of 0.5 rad/s); target 2 %.
    assert summary.max_velocity_error_percent_after_5_time_constants < 2.0
    assert summary.max_force_error_percent_after_5_time_constants < 2.0
    # joint7: b h / M = 11.8 at 1 ms, named in one line.
    assert [str(w.message).split(":")[0] for w in damping_warnings] == ["joint 'joint7'"]
    assert "b h / M = 11.8" in str(damping_warnings[0].message)


def test_the_xarm7_spin_row_stalls_without_it(xarm_table_task, monkeypatch):
    result, _ = spin_run(xarm_table_task, False, monkeypatch)
    # Measured 66.9 %: the spin row lags by 0.33 of 0.5 rad/s.
    assert result.summary.max_velocity_error_percent_after_5_time_constants > 30.0
    assert np.abs(result.log["velocity_error"][-1, 4]) > 0.1


# -- the impedance's answer to a measured force through the damped step (K_0 from J (M + h B)^-1 J^T) --

def impedance_step(damped_task, fast_law, h=1e-3):
    """One step of a discrete plant (the damped-wrist 3R arm, b h / M = 9.7, no contact geometry)
    under the impedance law's actuation and a wrench W = W_0 + lambda W_1 that acts on the arm and is
    the law's measured wrench, lambda chosen so that the contact row holds: E_f r-ddot + E_f-dot r-dot
    = 0 (a rigid contact), r-ddot = J (v+ - v) / h + J-dot q-dot. Returns (the velocity rows'
    e_p'' + K_v e_p' + K_p e_p, F_v, the force loop g_f, its prediction -M_f^-1 M_fp F_v (3.2-9) with
    the step's blocks, the law's K_0 applied to F_v from J M^-1 J^T and from J (M + h B)^-1 J^T)."""
    config = damped_task.default_config(mode="impedance-force")
    step_plant = MultibodyPlant(h)
    robot = damped_task.add_robot(step_plant, config)
    step_plant.Finalize()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointDampingWarning)
        scenario = build_scenario(config, with_loggers=False)
        plant, space, gains = scenario.controller_plant, scenario.constraint_space, config.gains
        controller = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains,
                                      "impedance-force", plant_time_step=h, fast_law=fast_law)
    q = np.asarray(damped_task.start_positions(scenario), dtype=float) + [0.02, -0.03, 0.04]
    v = np.array([0.1, -0.2, 0.3])
    K = controller.validated_gains()
    context = controller.CreateDefaultContext()
    xi, e_p = np.array([0.3]), np.array([0.004, -0.02])
    context.SetContinuousState(np.concatenate([xi, e_p]))
    desired = {"estimated_state": np.concatenate([q, v]), "desired_velocity": np.array([0.05, 0.0]),
               "desired_acceleration": np.array([0.1, -0.2]), "desired_force": np.array([10.0])}
    for name, value in desired.items():
        controller.GetInputPort(name).FixValue(context, value)
    frame = step_plant.GetFrameByName(robot.end_effector_frame)
    step_context = step_plant.CreateDefaultContext()
    step_plant.SetPositions(step_context, q)
    J_6 = step_plant.CalcJacobianSpatialVelocity(step_context, JacobianWrtVariable.kV, frame,
                                                 robot.end_effector_point, step_plant.world_frame(),
                                                 step_plant.world_frame())
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    plant.SetVelocities(plant_context, v)
    task = controller.kinematics.evaluate(plant_context)
    values = space.evaluate(task.configuration, task.velocity)
    E_p, E_f, J = values.velocity_projection, values.force_projection, task.jacobian

    def outcome(W):
        """(step's r-ddot, F_v, F) under the measured wrench W = [n; f] (world, at the point)."""
        controller.GetInputPort("measured_wrench").FixValue(context, W)
        u = controller.GetOutputPort("actuation").Eval(context).copy()
        step_context = step_plant.CreateDefaultContext()
        step_plant.SetPositions(step_context, q)
        step_plant.SetVelocities(step_context, v)
        step_plant.get_actuation_input_port().FixValue(step_context, u)
        step_plant.get_applied_generalized_force_input_port().FixValue(step_context, J_6.T @ W)
        Simulator(step_plant, step_context).AdvanceTo(h)                           # one step
        v_next = step_plant.GetVelocities(step_context)
        r_ddot = J @ (v_next - v) / h + task.bias
        return (r_ddot, controller.GetOutputPort("tangential_force").Eval(context).copy(),
                controller.GetOutputPort("force").Eval(context).copy())

    W_0 = np.array([0.1, -0.3, 0.2, 4.0, -3.0, 2.0])
    W_1 = np.array([0.05, 0.1, -0.02, 1.0, 2.0, -3.0])
    (r_0, F_v0, F_0), (r_1, F_v1, F_1) = outcome(W_0), outcome(W_0 + W_1)
    row = lambda r: E_f @ r + values.force_curvature
    lam = -row(r_0)[0] / (row(r_1) - row(r_0))[0]
    r_ddot, F_v, F = r_0 + lam * (r_1 - r_0), F_v0 + lam * (F_v1 - F_v0), F_0 + lam * (F_1 - F_0)
    np.testing.assert_allclose(row(outcome(W_0 + lam * W_1)[0]), 0.0, atol=1e-9)      # affine: lambda exact
    velocity_error = E_p @ task.velocity - desired["desired_velocity"]
    impedance = (E_p @ r_ddot + values.velocity_curvature - desired["desired_acceleration"]
                 + K.velocity @ velocity_error + K.position @ e_p)
    g_f = (1.0 + K.force_proportional[0, 0]) * (F[0] - 10.0) + K.force_integral[0, 0] * xi[0]
    M = plant.CalcMassMatrix(plant_context)
    mobility = J @ np.linalg.solve(M, J.T)
    step_mobility = J @ np.linalg.solve(M + h * np.diag(joint_damping(plant)), J.T)
    M_f, M_fp, _ = impedance_blocks(E_p, E_f, step_mobility)
    return (impedance, F_v, g_f, -np.linalg.solve(M_f, M_fp @ F_v)[0],
            impedance_gain(E_p, E_f, mobility) @ F_v, impedance_gain(E_p, E_f, step_mobility) @ F_v)


@pytest.mark.parametrize("fast_law", [True, False], ids=["compiled", "generic"])
def test_the_impedance_answers_a_force_through_the_damped_step(damped_task, fast_law, monkeypatch):
    """On the discrete plant the arm answers a force through (M + h B)^-1 (control.damping): with K_0
    and the force rows' blocks from J (M + h B)^-1 J^T the step realizes the unit-mass impedance
    e_p'' + K_v e_p' + K_p e_p = F_v and g_f = -M_f^-1 M_fp F_v (3.2-11) to rounding (measured
    1e-13 against |F_v| = 2.4). "compiled": the compiled law from the first tick (control.fast_compile)."""
    monkeypatch.setattr(fast_compile, "_POLICY", ["foreground"])
    impedance, F_v, g_f, g_f_predicted, _, _ = impedance_step(damped_task, fast_law)
    assert np.linalg.norm(F_v) > 1.0                                          # a real tangential force
    np.testing.assert_allclose(impedance, F_v, atol=1e-9 * np.linalg.norm(F_v))
    np.testing.assert_allclose(g_f, g_f_predicted, atol=1e-9 * abs(g_f_predicted))


def test_k0_from_the_continuous_mobility_misses_the_impedance_on_the_damped_step(damped_task, monkeypatch):
    """The law before: K_0 from J M^-1 J^T (the generic law with step_task_mobility bypassed) leaves
    (K_0 - K_0,step) F_v in e_p'' + K_v e_p' + K_p e_p - F_v: measured (0.41, -2.31) against
    F_v = (2.40, 0.46) on this wrist (b h / M = 9.7)."""
    monkeypatch.setattr(law_module, "step_task_mobility", lambda J, M, mobility, damping, step: mobility)
    impedance, F_v, _, _, K_0_F_v, K_0_step_F_v = impedance_step(damped_task, False)
    np.testing.assert_allclose(impedance - F_v, K_0_F_v - K_0_step_F_v, atol=1e-9 * np.linalg.norm(F_v))
    assert np.linalg.norm(impedance - F_v) > 0.5 * np.linalg.norm(F_v)


def test_the_autodiff_law_builds_k0_from_the_damped_step_too(damped_task):
    """The AutoDiffXd copy of the impedance controller on the damped discrete step (h = 1 ms) runs
    step_task_mobility on AutoDiffXd M and gives the float law's actuation; h changes it (K_0 and
    h B a*), so the equality is not that of two undamped laws."""
    config = damped_task.default_config(mode="impedance-force")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointDampingWarning)
        scenario = build_scenario(config, with_loggers=False)
    q = np.asarray(damped_task.start_positions(scenario), dtype=float)
    inputs = {"estimated_state": np.concatenate([q, [0.1, -0.2, 0.3]]), "desired_velocity": np.array([0.05, 0.0]),
              "desired_acceleration": np.zeros(2), "desired_force": np.array([10.0]),
              "measured_wrench": np.array([0.1, -0.3, 0.2, 4.0, -3.0, 2.0])}
    actuation = {}
    for h in (1e-3, 0.0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JointDampingWarning)
            controller = HybridController(scenario.controller_plant, scenario.robot.end_effector_frame,
                                          scenario.robot.end_effector_point, scenario.constraint_space, config.gains,
                                          "impedance-force", plant_time_step=h)
        for system in (controller, controller.ToAutoDiffXd()):
            context = system.CreateDefaultContext()
            for name, value in inputs.items():
                system.GetInputPort(name).FixValue(context, value)
            u = system.GetOutputPort("actuation").Eval(context)
            actuation[h, system is controller] = np.array([a.value() if hasattr(a, "value") else a for a in u])
    np.testing.assert_allclose(actuation[1e-3, False], actuation[1e-3, True], rtol=1e-12, atol=1e-12)
    assert np.abs(actuation[1e-3, True] - actuation[0.0, True]).max() > 0.1
