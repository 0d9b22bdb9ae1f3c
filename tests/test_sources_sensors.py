"""Desired-motion sources, the low-pass filter and the contact sensor's sign and shift."""

import math

import numpy as np
import pytest
import sympy

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid import ConstraintSpace, KernelVelocityProjection
from drake_hybrid.core.errors import DimensionError, UnknownVariableError
from drake_hybrid.core.linalg import value
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.systems.low_pass_filter import LowPassFilter
from drake_hybrid.systems.sources import DesiredFieldSource, Profile, ProfileSource
from drake_hybrid.tasks.plant import build_controller_plant
from drake_hybrid.tasks.registry import get_task

EPS = 1e-6


@pytest.mark.parametrize("profile", [
    Profile(kind="constant", value=[0.1, -0.2]),
    Profile(kind="smooth_step", value=[0.0, 0.0], final_value=[0.2, -0.1], start_time=0.1, duration=0.5),
    Profile(kind="sine", value=[0.05, 0.0], amplitude=[0.1, 0.3], frequency=0.7, start_time=0.2),
])
def test_profile_source_acceleration_is_the_time_derivative(profile):
    dut = ProfileSource(profile, Profile(kind="constant", value=[-5.0]), 2, 1)
    context = dut.CreateDefaultContext()
    for t in (0.0, 0.13, 0.35, 0.61, 1.2):
        context.SetTime(t)
        acceleration = dut.GetOutputPort("desired_acceleration").Eval(context)
        velocities = []
        for dt in (EPS, -EPS):
            context.SetTime(t + dt)
            velocities.append(dut.GetOutputPort("desired_velocity").Eval(context).copy())
        np.testing.assert_allclose(acceleration, (velocities[0] - velocities[1]) / (2 * EPS), atol=1e-7)
        context.SetTime(t)
        np.testing.assert_allclose(dut.GetOutputPort("desired_force").Eval(context), [-5.0])
    assert dut.ToAutoDiffXd() is not None


def test_profile_validation():
    with pytest.raises(DimensionError, match="velocity_profile: value must have 2 entries, got 1"):
        ProfileSource(Profile(value=[0.1]), Profile(value=[-1.0]), 2, 1)
    with pytest.raises(ValueError, match=r"profile.kind must be one of constant, smooth_step, sine, got 'ramp'"):
        ProfileSource(Profile(kind="ramp", value=[0.1, 0]), Profile(value=[-1.0]), 2, 1)


def field_source(projection="given"):
    task = get_task("window-washing")
    config = task.default_config()
    plant, robot = build_controller_plant(task, config)
    space = task.constraint_space(config)
    chart = space.chart
    x, y, theta = chart.symbols
    if projection == "kernel":
        anchor = np.array([0.9, 0.98, 1.5])
        space = ConstraintSpace(space.constraint, KernelVelocityProjection(space.constraint, anchor))
    # A wiping field: faster near x = 1, turning the tool toward the window's normal.
    velocity_field = [0.1 + 0.2 * sympy.sin(x), 0, -0.5 * (theta - sympy.pi / 2)]
    force_field = [-8.0 - 2.0 * x]
    source = DesiredFieldSource(plant, robot.end_effector_frame, robot.end_effector_point, space, velocity_field,
                                force_field)
    return task, config, plant, source, space


@pytest.mark.parametrize("projection", ["given", "kernel"])
def test_field_source_acceleration_is_the_derivative_along_the_motion(projection, rng):
    task, config, plant, dut, space = field_source(projection)
    context = dut.CreateDefaultContext()
    q = task.inverse_kinematics(config, 0.95, 0.98, 1.4)
    v = rng.normal(size=3) * 0.3
    dut.get_input_port(0).FixValue(context, np.concatenate([q, v]))
    acceleration = dut.GetOutputPort("desired_acceleration").Eval(context).copy()
    velocities = []
    for dt in (EPS, -EPS):
        dut.get_input_port(0).FixValue(context, np.concatenate([q + dt * v, v]))
        velocities.append(dut.GetOutputPort("desired_velocity").Eval(context).copy())
    np.testing.assert_allclose(acceleration, (velocities[0] - velocities[1]) / (2 * EPS), atol=1e-7)
    dut.get_input_port(0).FixValue(context, np.concatenate([q, v]))
    x = dut.kinematics.evaluate(dut._plant_context_cache.Eval(context)).configuration
    np.testing.assert_allclose(dut.GetOutputPort("desired_force").Eval(context), [-8.0 - 2.0 * x[0]])
    if projection == "given":   # r-dot_pd = E_p Y_d = (Y_x, Y_theta) with E_p = [[1 0 0], [0 0 1]]
        np.testing.assert_allclose(dut.GetOutputPort("desired_velocity").Eval(context),
                                   [0.1 + 0.2 * math.sin(x[0]), -0.5 * (x[2] - math.pi / 2)])


def test_field_source_autodiff_equals_float(rng):
    task, config, plant, dut, space = field_source()
    dut_ad = dut.ToAutoDiffXd()
    q = task.inverse_kinematics(config, 0.95, 0.98, 1.4)
    state = np.concatenate([q, rng.normal(size=3)])
    context, context_ad = dut.CreateDefaultContext(), dut_ad.CreateDefaultContext()
    dut.get_input_port(0).FixValue(context, state)
    dut_ad.get_input_port(0).FixValue(context_ad, np.array([AutoDiffXd(s) for s in state], dtype=object))
    for name in ("desired_velocity", "desired_acceleration", "desired_force"):
        np.testing.assert_allclose(value(dut_ad.GetOutputPort(name).Eval(context_ad)),
                                   dut.GetOutputPort(name).Eval(context), atol=1e-13)


def test_field_source_validates_its_fields():
    task, config, plant, _, space = field_source()
    with pytest.raises(DimensionError, match="velocity field must have d = 3 entries"):
        DesiredFieldSource(plant, "tip", np.zeros(3), space, [0.1, 0.0], [-5.0])
    with pytest.raises(UnknownVariableError, match=r"force field uses variables \['s'\]"):
        DesiredFieldSource(plant, "tip", np.zeros(3), space, [0.1, 0, 0], [sympy.Symbol("s")])


@pytest.mark.parametrize("period", [None, 1e-3])
def test_low_pass_filter_step_response(period):
    from pydrake.systems.analysis import Simulator

    bandwidth = 20.0
    dut = LowPassFilter(2, bandwidth, period)
    simulator = Simulator(dut)
    simulator.get_mutable_integrator().set_target_accuracy(1e-10)
    context = simulator.get_mutable_context()
    dut.get_input_port(0).FixValue(context, [1.0, -2.0])
    dut.set_initial_output(context, [0.0, 0.0])
    t = 0.02
    simulator.AdvanceTo(t)
    if period is None:
        expected = 1 - math.exp(-2 * math.pi * bandwidth * t)
        np.testing.assert_allclose(dut.get_output_port(0).Eval(context), [expected, -2 * expected], rtol=1e-6)
    else:
        # AdvanceTo(20 ms) applies the updates at 0, 1, ..., 19 ms: 20 exact steps of the held input,
        # which equal the continuous response at 20 ms.
        expected = 1 - math.exp(-2 * math.pi * bandwidth * period) ** 20
        np.testing.assert_allclose(dut.get_output_port(0).Eval(context), [expected, -2 * expected], rtol=1e-9)
    with pytest.raises(ValueError, match=r"bandwidth_hz must be a finite number > 0 \(Hz\)"):
        LowPassFilter(2, 0.0)


def test_contact_sensor_sign_and_shift():
    """Pressing up on the window: the wrench on the robot at the pad centre is (0, 0, 0, 0, 0, -F_d) and
    the torque at another point is n = p x f."""
    task = get_task("window-washing")
    config = task.default_config()
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    sensor = scenario.sensor
    wrench = sensor.get_output_port(0).Eval(sensor.GetMyContextFromRoot(context))
    np.testing.assert_allclose(wrench[3:], [0, 0, -10.0], atol=1e-6)
    np.testing.assert_allclose(wrench[:3], 0, atol=1e-3)              # through the pad centre (ball pad)


@pytest.mark.parametrize("task_name, contact_model", [("window-washing", "hydroelastic_with_fallback"),
                                                      ("window-washing", "point"), ("crank-turning", None)])
def test_float_sensors_equal_their_generic_calculation(task_name, contact_model):
    """The float sensors' plain-float arithmetic (``_calc_wrench_float``) gives the generic (float and
    AutoDiffXd) calculation's wrench to rounding, while pressing: the contact sensor on hydroelastic and
    point contact, the wrist sensor (crank) with its tool weight and the shift from the weld to P."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import BasicVector

    config = get_task(task_name).default_config()
    if contact_model is not None:
        config.plant.contact_model = contact_model
    scenario = build_scenario(config, with_loggers=False)
    simulator = Simulator(scenario.diagram)
    set_initial_conditions(scenario, simulator.get_mutable_context())
    simulator.AdvanceTo(0.02)
    sensor = scenario.sensor
    context = sensor.GetMyContextFromRoot(simulator.get_context())
    fast, generic = BasicVector(6), BasicVector(6)
    sensor._calc_wrench_float(context, fast)
    sensor._calc_wrench(context, generic)
    assert np.linalg.norm(generic.value()[3:]) > 1.0                      # in contact
    np.testing.assert_allclose(fast.value(), generic.value(), rtol=1e-12, atol=1e-12 * np.abs(generic.value()).max())
    np.testing.assert_array_equal(sensor.get_output_port(0).Eval(context), fast.value())


@pytest.mark.parametrize("contact_model", ["hydroelastic_with_fallback", "point"])
def test_contact_sensor_reads_the_steps_own_solve_about_p_where_it_was(contact_model):
    """On a discrete plant with sampled output ports (one contact solve per step) the sensor shifts the
    step's contact forces to P at the configuration q_k the step solved them at (its sampled point): the
    wrench it reports, mapped by J(q_k)^T, is the plant's own generalized contact force of that step to
    rounding. Shifted to the current P instead (the pose after the step), the lever arm is off by the
    step's motion v h, a false moment of about |f| |v| h (docs/drake_notes.md), far above rounding."""
    from pydrake.multibody.tree import JacobianWrtVariable
    from pydrake.systems.analysis import Simulator

    config = get_task("window-washing").default_config()
    config.plant.contact_model = contact_model
    scenario = build_scenario(config, with_loggers=False)
    plant, sensor, arm = scenario.plant, scenario.sensor, scenario.robot.arm
    assert plant.has_sampled_output_ports() and sensor.samples_point
    simulator = Simulator(scenario.diagram)
    context = simulator.get_mutable_context()
    set_initial_conditions(scenario, context)
    plant_context, sensor_context = plant.GetMyContextFromRoot(context), sensor.GetMyContextFromRoot(context)
    frame = sensor._frame
    solve_context = plant.CreateDefaultContext()
    h = plant.time_step()
    sampled_errors, current_errors, torques = [], [], []
    for k in range(1, 120):
        q_before_step = plant.GetPositions(plant_context)
        simulator.AdvanceTo((k + 0.5) * h)
        if k < 100:                                                       # sliding from rest first
            continue
        plant.SetPositions(solve_context, q_before_step)
        J = plant.CalcJacobianSpatialVelocity(solve_context, JacobianWrtVariable.kV, frame,
                                              scenario.robot.end_effector_point, plant.world_frame(),
                                              plant.world_frame())
        tau_contact = plant.get_generalized_contact_forces_output_port(arm).Eval(plant_context)
        wrench = sensor.get_output_port(0).Eval(sensor_context)
        p_now = sensor._current_point(sensor_context)
        # The same forces shifted to the current P: n_now = n_sampled - (p_now - p_sampled) x f.
        p_sampled = sensor_context.get_discrete_state(0).value()
        at_current = np.concatenate([wrench[:3] - np.cross(p_now - p_sampled, wrench[3:]), wrench[3:]])
        sampled_errors.append(np.abs(J.T @ wrench - tau_contact).max())
        current_errors.append(np.abs(J.T @ at_current - tau_contact).max())
        torques.append(np.abs(tau_contact).max())
    speed = np.linalg.norm(scenario.kinematics.evaluate(plant_context).velocity[:2])
    assert speed > 0.02                                                   # sliding
    assert max(sampled_errors) < 1e-12 * max(torques)
    assert min(current_errors) > 0.1 * 10.0 * speed * h                   # |f| |v| h, f = 10 N
