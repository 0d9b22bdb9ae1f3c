"""HybridController: ports, scalar types, feedthrough, and the closed loop the law produces.

The closed-loop checks solve the rigid-contact dynamics of docs/theory.md §4 with Drake's M, h, g:
    [M, -J^T E_f^T (I + K_fp); E_f J, 0] [q-ddot; F] = [tau_a - h - g; -(E_f J-dot q-dot + E_f-dot r-dot)]
and check (3.1-14), (3.1-15), Remark 3 and (3.2-11) to rounding.
"""

import numpy as np
import pytest

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid import ArgumentError, GainError
from drake_hybrid.control.controller import HybridController, HybridController_
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.linalg import value
from drake_hybrid.tasks.plant import build_controller_plant
from drake_hybrid.tasks.registry import get_task

MODES = ["velocity-force", "position-force", "impedance-force"]
INPUTS = ["estimated_state", "measured_wrench", "desired_velocity", "desired_acceleration", "desired_force"]
OUTPUTS = ["actuation", "computed_actuation", "velocity_error", "force_error", "constraint_value",
           "projected_velocity", "force", "tangential_force", "wrench_valid", "position_error"]


def window_parts(joints=3):
    task = get_task("window-washing")
    config = task.default_config()
    config.task_parameters["joints"] = joints
    plant, robot = build_controller_plant(task, config)
    return task, config, plant, robot, task.constraint_space(config)


def make_dut(mode="velocity-force", control_period=None, joints=3, gains=None):
    task, config, plant, robot, space = window_parts(joints)
    gains = gains or HybridGains(velocity=[6.0, 4.0], position=[9.0, 5.0], force_proportional=0.5, force_integral=3.0,
                                 null_space_damping=5.0)
    dut = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains, mode,
                           control_period)
    return dut, plant, space


def fix_inputs(dut, context, q, v, wrench, desired_velocity=(0.1, -0.2), desired_acceleration=(0.3, 0.1),
               desired_force=(-6.0,)):
    dut.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, v]))
    dut.GetInputPort("measured_wrench").FixValue(context, wrench)
    dut.GetInputPort("desired_velocity").FixValue(context, np.asarray(desired_velocity))
    dut.GetInputPort("desired_acceleration").FixValue(context, np.asarray(desired_acceleration))
    dut.GetInputPort("desired_force").FixValue(context, np.asarray(desired_force))


def test_port_names_and_sizes():
    dut, plant, _ = make_dut("position-force")
    assert [dut.get_input_port(i).get_name() for i in range(dut.num_input_ports())] == INPUTS
    assert [dut.get_input_port(i).size() for i in range(dut.num_input_ports())] == [6, 6, 2, 2, 1]
    assert [dut.get_output_port(i).get_name() for i in range(dut.num_output_ports())] == OUTPUTS
    assert [dut.get_output_port(i).size() for i in range(dut.num_output_ports())] == [3, 3, 2, 1, 1, 2, 1, 2, 1, 2]
    assert dut.CreateDefaultContext().num_continuous_states() == 1 + 2           # xi and e_p
    velocity_dut, _, _ = make_dut("velocity-force")
    assert velocity_dut.CreateDefaultContext().num_continuous_states() == 1       # xi only
    sampled, _, _ = make_dut("velocity-force", control_period=1e-3)
    context = sampled.CreateDefaultContext()
    assert context.num_continuous_states() == 0
    assert context.get_discrete_state(0).size() == 1 + 3                         # xi and the held torque


def test_direct_feedthrough_continuous_and_sampled():
    continuous, _, _ = make_dut()
    sampled, _, _ = make_dut(control_period=1e-3)
    actuation = continuous.GetOutputPort("actuation").get_index()
    for name in INPUTS:
        index = continuous.GetInputPort(name).get_index()
        assert continuous.HasDirectFeedthrough(index, actuation), name
        assert not sampled.HasDirectFeedthrough(index, sampled.GetOutputPort("actuation").get_index()), name
        # The actuation the tick computes is the inputs' (for a system that ticks with the law).
        assert sampled.HasDirectFeedthrough(index, sampled.GetOutputPort("computed_actuation").get_index()), name
    # Logging outputs are feedthrough of the measurement; position_error is state only.
    assert continuous.HasDirectFeedthrough(continuous.GetInputPort("measured_wrench").get_index(),
                                           continuous.GetOutputPort("force_error").get_index())
    assert not continuous.HasDirectFeedthrough(continuous.GetInputPort("estimated_state").get_index(),
                                               continuous.GetOutputPort("position_error").get_index())


def rigid_contact_closed_loop(dut, plant, space, q, v, xi, e_p, desired, rng, tangential=None):
    """Solve the rigid-contact dynamics under the controller; return what the loops should zero."""
    context = dut.CreateDefaultContext()
    if dut.control_period is None:
        state = np.concatenate([xi, e_p]) if dut.mode.integrates_position else xi
        context.SetContinuousState(state)
    desired_velocity, desired_acceleration, desired_force = desired
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    plant.SetVelocities(plant_context, v)
    task = dut.kinematics.evaluate(plant_context)
    values = space.evaluate(task.configuration, task.velocity)
    E_f, E_p = values.force_projection, values.velocity_projection
    chart = space.chart

    def torque(F, F_v):
        # The measured wrench of a generalized force w = E_f^T F + E_p^T F_v: the spatial force B^+T w.
        w = E_f.T @ F + E_p.T @ F_v
        spatial = np.linalg.lstsq(chart._selector, w, rcond=None)[0] if hasattr(chart, "_selector") else None
        fix_inputs(dut, context, q, v, spatial, desired_velocity, desired_acceleration, desired_force)
        return dut.GetOutputPort("actuation").Eval(context), w

    F_v = np.zeros(2) if tangential is None else tangential
    tau_a, _ = torque(np.zeros(1), F_v)                   # torque with F = 0: the F-independent part
    tau_1, _ = torque(np.ones(1), F_v)
    B = (tau_1 - tau_a)[:, None]                          # d tau / dF = J^T E_f^T K_fp
    M = plant.CalcMassMatrix(plant_context)
    hg = plant.CalcBiasTerm(plant_context) - plant.CalcGravityGeneralizedForces(plant_context)
    J = task.jacobian
    n = len(q)
    K = np.block([[M, -(B + J.T @ E_f.T)], [E_f @ J, np.zeros((1, 1))]])
    rhs = np.concatenate([tau_a - hg + J.T @ E_p.T @ F_v, -(E_f @ task.bias + values.force_curvature)])
    solution = np.linalg.solve(K, rhs)
    q_ddot, F = solution[:n], solution[n:]
    r_ddot = J @ q_ddot + task.bias
    velocity_error = E_p @ task.velocity - desired_velocity
    return dict(r_ddot_p=E_p @ r_ddot + values.velocity_curvature, velocity_error=velocity_error, F=F,
                constraint_acceleration=E_f @ r_ddot + values.force_curvature, values=values, task=task, M=M)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("joints", [3, 4])
def test_closed_loop_is_the_designed_one_under_rigid_contact(mode, joints, rng):
    dut, plant, space = make_dut(mode, joints=joints)
    gains = dut.validated_gains()
    for _ in range(3):
        q = dut_random_positions(joints, rng)
        v = rng.normal(size=joints) * 0.3
        xi, e_p = rng.normal(size=1) * 0.2, rng.normal(size=2) * 0.05
        desired = (rng.normal(size=2) * 0.1, rng.normal(size=2) * 0.2, np.array([-8.0]))
        F_v = rng.normal(size=2) if mode == "impedance-force" else np.zeros(2)
        out = rigid_contact_closed_loop(dut, plant, space, q, v, xi, e_p, desired, rng, tangential=F_v)
        e_f = out["F"] - desired[2]
        a_p = desired[1] - gains.velocity @ out["velocity_error"]
        if mode != "velocity-force":
            a_p = a_p - gains.position @ e_p
        np.testing.assert_allclose(out["constraint_acceleration"], 0, atol=1e-10)        # stays on N  (3.0-7)
        if mode == "impedance-force":
            # (3.2-11): e_p'' + K_v e_p' + K_p e_p = F_v, (I + K_fp) e_f + K_fi xi = -M_f^-1 M_fp F_v
            np.testing.assert_allclose(out["r_ddot_p"], a_p + F_v, atol=1e-9)
            values, task = out["values"], out["task"]
            mobility = task.jacobian @ np.linalg.solve(out["M"], task.jacobian.T)
            M_f = values.force_projection @ mobility @ values.force_projection.T
            M_fp = values.force_projection @ mobility @ values.velocity_projection.T
            np.testing.assert_allclose((1 + gains.force_proportional) @ e_f + gains.force_integral @ xi,
                                       -np.linalg.solve(M_f, M_fp @ F_v), atol=1e-9)
        else:
            np.testing.assert_allclose(out["r_ddot_p"], a_p, atol=1e-9)                  # (3.1-15) / Remark 3
            np.testing.assert_allclose((1 + gains.force_proportional) @ e_f + gains.force_integral @ xi, 0,
                                       atol=1e-9)                                         # (3.1-14)


@pytest.mark.parametrize("mode", MODES)
def test_force_damping_leaves_the_rigid_contact_design_as_it_is(mode, rng):
    """a_f = -K_fd C-dot (HybridGains.force_damping) acts only where the force rows move: under rigid contact,
    at a velocity along the constraint (E_f r-dot = 0), the closed loop is still (3.1-14), (3.1-15); where
    they move (E_f r-dot != 0, which rigid contact cannot hold) the contact's force answers for it."""
    gains = HybridGains(velocity=[6.0, 4.0], position=[9.0, 5.0], force_proportional=0.5, force_integral=3.0,
                        force_damping=40.0)
    dut, plant, space = make_dut(mode, gains=gains)
    plain, plain_plant, _ = make_dut(mode)
    validated = dut.validated_gains()
    model = dut.kinematics.plant
    context = model.CreateDefaultContext()
    for _ in range(3):
        q = dut_random_positions(3, rng)
        model.SetPositions(context, q)
        task = dut.kinematics.evaluate(context)
        E_f = space.evaluate(task.configuration, task.velocity).force_projection
        along = np.linalg.svd(E_f @ task.jacobian)[2][1:].T          # joint velocities with C-dot = 0
        v = along @ rng.normal(size=along.shape[1]) * 0.3
        xi, e_p = rng.normal(size=1) * 0.2, rng.normal(size=2) * 0.05
        desired = (rng.normal(size=2) * 0.1, rng.normal(size=2) * 0.2, np.array([-8.0]))
        out = rigid_contact_closed_loop(dut, plant, space, q, v, xi, e_p, desired, rng)
        reference = rigid_contact_closed_loop(plain, plain_plant, space, q, v, xi, e_p, desired, rng)
        np.testing.assert_allclose(out["F"], reference["F"], atol=1e-9)
        np.testing.assert_allclose(out["r_ddot_p"], reference["r_ddot_p"], atol=1e-9)
        e_f = out["F"] - desired[2]
        np.testing.assert_allclose((1 + validated.force_proportional) @ e_f + validated.force_integral @ xi, 0,
                                   atol=1e-9)
        across = v + 0.2 * np.linalg.pinv(E_f @ task.jacobian)[:, 0]          # C-dot != 0
        moving = rigid_contact_closed_loop(dut, plant, space, q, across, xi, e_p, desired, rng)
        still = rigid_contact_closed_loop(plain, plain_plant, space, q, across, xi, e_p, desired, rng)
        assert abs(float(moving["F"][0] - still["F"][0])) > 1e-3         # K_fd acts where C-dot != 0


def dut_random_positions(joints, rng):
    task, config, *_ = window_parts(joints)
    x, theta = rng.uniform(0.7, 1.3), rng.uniform(1.2, 1.9)
    return task.inverse_kinematics(config, x, 0.98 + rng.uniform(-0.05, 0.05), theta)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("control_period", [None, 1e-3])
def test_autodiff_instance_equals_float(mode, control_period, rng):
    dut, plant, _ = make_dut(mode, control_period)
    dut_ad = dut.ToAutoDiffXd()
    assert isinstance(dut_ad, HybridController_[AutoDiffXd])
    q, v = dut_random_positions(3, rng), rng.normal(size=3) * 0.2
    wrench = np.array([0.01, -0.02, 0.03, 0.5, -0.1, -6.5])
    context, context_ad = dut.CreateDefaultContext(), dut_ad.CreateDefaultContext()
    state = rng.normal(size=context.num_continuous_states() or context.get_discrete_state(0).size()) * 0.1
    for ctx, system in ((context, dut), (context_ad, dut_ad)):
        if control_period is None:
            ctx.SetContinuousState(state)
        else:
            ctx.SetDiscreteState(0, state)
        fix_inputs(system, ctx, q, v, wrench)
    for name in OUTPUTS:
        expected = dut.GetOutputPort(name).Eval(context)
        got = dut_ad.GetOutputPort(name).Eval(context_ad)
        np.testing.assert_allclose(value(got), expected, rtol=1e-12, atol=1e-12, err_msg=name)
    if control_period is None:
        np.testing.assert_allclose(value(dut_ad.EvalTimeDerivatives(context_ad).CopyToVector()),
                                   dut.EvalTimeDerivatives(context).CopyToVector(), atol=1e-12)
    else:
        np.testing.assert_allclose(value(dut_ad.EvalUniquePeriodicDiscreteUpdate(context_ad).get_vector(0).CopyToVector()),
                                   dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value(), atol=1e-10)


def test_autodiff_derivative_matches_finite_differences(rng):
    """d(actuation)/d(state) through the AutoDiffXd controller equals central differences."""
    dut, plant, _ = make_dut("position-force")
    dut_ad = dut.ToAutoDiffXd()
    q, v = dut_random_positions(3, rng), rng.normal(size=3) * 0.2
    wrench = np.array([0.0, 0.0, 0.0, 0.1, 0.0, -6.5])
    context, context_ad = dut.CreateDefaultContext(), dut_ad.CreateDefaultContext()
    x = np.concatenate([q, v])
    seeded = np.array([AutoDiffXd(xi, np.eye(6)[i]) for i, xi in enumerate(x)], dtype=object)
    fix_inputs(dut_ad, context_ad, seeded[:3], seeded[3:], wrench)
    jacobian = np.array([u.derivatives() for u in dut_ad.GetOutputPort("actuation").Eval(context_ad)])
    eps = 1e-6
    columns = []
    for i in range(6):
        values = []
        for sign in (1, -1):
            x_eps = x + sign * eps * np.eye(6)[i]
            fix_inputs(dut, context, x_eps[:3], x_eps[3:], wrench)
            values.append(dut.GetOutputPort("actuation").Eval(context).copy())
        columns.append((values[0] - values[1]) / (2 * eps))
    np.testing.assert_allclose(jacobian, np.column_stack(columns), rtol=1e-6, atol=1e-6)


def test_nan_wrench_gives_finite_torque_and_holds_the_integral(rng):
    dut, _, _ = make_dut(control_period=1e-3)
    context = dut.CreateDefaultContext()
    context.SetDiscreteState(0, np.array([0.1, 0, 0, 0]))
    q, v = dut_random_positions(3, rng), np.zeros(3)
    fix_inputs(dut, context, q, v, np.array([np.nan, 0, 0, 0, 0, -5.0]))
    update = dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value()
    assert np.all(np.isfinite(update))
    assert update[0] == pytest.approx(0.1)              # xi held during a dropout
    # What the wrench gives reads NaN, never a perfect match; wrench_valid says why.
    for name in ("force_error", "force", "tangential_force"):
        assert np.all(np.isnan(dut.GetOutputPort(name).Eval(context))), name
    assert dut.GetOutputPort("wrench_valid").Eval(context)[0] == 0.0
    assert np.all(np.isfinite(dut.GetOutputPort("velocity_error").Eval(context)))
    fix_inputs(dut, context, q, v, np.array([0, 0, 0, 0, 0, -5.0]))
    assert dut.GetOutputPort("wrench_valid").Eval(context)[0] == 1.0
    assert np.all(np.isfinite(dut.GetOutputPort("force_error").Eval(context)))


def test_sampled_controller_ticks_just_before_the_plant_step():
    dut, _, _ = make_dut(control_period=2e-3)
    timing = dut.GetUniquePeriodicDiscreteUpdateAttribute()
    assert timing.period_sec() == pytest.approx(2e-3)
    assert 0 < 2e-3 - timing.offset_sec() < 1e-8


def test_the_computed_actuation_is_what_the_tick_stores_and_the_held_one_then_holds():
    """A sampled law's ``computed_actuation`` at a tick's time is the torque its update stores: after the
    update ``actuation`` reads it, bit for bit, while ``computed_actuation`` already follows the new state."""
    dut, plant, _ = make_dut("position-force", control_period=1e-3)
    context = dut.CreateDefaultContext()
    q, v = np.array([0.4, -0.9, 0.6]), np.array([0.05, -0.02, 0.01])
    fix_inputs(dut, context, q, v, np.array([0.0, 0.0, 0.0, 0.0, 3.0, -5.0]))
    context.SetTime(1e-3 * (1.0 - 1e-6))
    computed = dut.GetOutputPort("computed_actuation").Eval(context).copy()
    held_before = dut.GetOutputPort("actuation").Eval(context).copy()
    context.SetDiscreteState(dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).CopyToVector())
    assert np.array_equal(dut.GetOutputPort("actuation").Eval(context), computed)
    assert not np.array_equal(held_before, computed)
    # The integrals moved: the law now computes another torque, the held one stays until the next tick.
    assert not np.array_equal(dut.GetOutputPort("computed_actuation").Eval(context), computed)


def test_bad_inputs_raise_clear_errors():
    task, config, plant, robot, space = window_parts()
    with pytest.raises(GainError, match=r"gain velocity \(K_v\) must be positive definite; its eigenvalues are"):
        HybridController(plant, "tip", np.zeros(3), space, HybridGains(velocity=[5.0, -1.0]))
    with pytest.raises(GainError, match=r"gain force_integral \(K_fi\) has 2 diagonal entries; for 1 row it must be a scalar"):
        HybridController(plant, "tip", np.zeros(3), space, HybridGains(force_integral=[1.0, 2.0]))
    with pytest.raises(GainError, match=r"gain position \(K_p\) must be symmetric"):
        HybridController(plant, "tip", np.zeros(3), space, HybridGains(position=[1.0, 2.0, 0.0, 1.0]),
                         mode="position-force")
    with pytest.raises(GainError, match=r"force_proportional \(K_fp\) must be positive semidefinite"):
        HybridController(plant, "tip", np.zeros(3), space, HybridGains(force_proportional=-0.5))
    with pytest.raises(ValueError, match="frame 'flange' is not in the plant; its frames are"):
        HybridController(plant, "flange", np.zeros(3), space)
    with pytest.raises(ValueError, match="unknown control mode 'force'"):
        HybridController(plant, "tip", np.zeros(3), space, mode="force")
    with pytest.raises(ValueError, match=r"control_period must be a finite number > 0 \(s\) or None, got -0.001"):
        HybridController(plant, "tip", np.zeros(3), space, control_period=-1e-3)
    with pytest.raises(ValueError, match="sampled_diagnostics needs a control_period"):
        HybridController(plant, "tip", np.zeros(3), space, sampled_diagnostics=True)
    with pytest.raises(ValueError, match=r"end_effector_point must be a vector of 3 finite numbers \(m\), got \[0, 0\]"):
        HybridController(plant, "tip", np.zeros(2), space)
    from drake_hybrid import ConstraintSpace, EulerZXZChart, KernelVelocityProjection, crank_constraint
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0)
    r0 = np.array([-np.sin(0.3), np.cos(0.3), 0.3, 0.3, np.pi / 2, 0.0])
    spatial = ConstraintSpace(crank, KernelVelocityProjection(crank, r0))
    with pytest.raises(ValueError, match="the task has d = 6 coordinates .* only n = 3 joints"):
        HybridController(plant, "tip", np.zeros(3), spatial)


def test_scalar_conversion_keeps_every_argument_and_contexts_do_not_share_scratch():
    """ToAutoDiffXd rebuilds the controller from every argument it was given (none falls back to a
    default), and each context owns its MultibodyForces scratch (a cache entry)."""
    from drake_hybrid.scenario.builder import build_scenario
    from drake_hybrid.tasks.registry import get_task

    config = get_task("window-washing").default_config()
    config.safety.max_joint_acceleration = 12.0
    controller = build_scenario(config, with_loggers=True).controller
    converted = controller.ToAutoDiffXd()
    assert converted._arguments.keys() == controller._arguments.keys()
    for name, value in controller._arguments.items():
        assert converted._arguments[name] is value, name
    assert converted.sampled_diagnostics and converted._max_joint_acceleration == 12.0
    first, second = controller.CreateDefaultContext(), controller.CreateDefaultContext()
    for context in (first, second):
        controller.get_input_port(0).FixValue(context, np.zeros(2 * controller.num_joints))
    def forces(context):                            # the per-context MultibodyForces in the law's cache entry
        return controller._solution_cache.get_mutable_cache_entry_value(context).GetMutableValueOrThrow().forces

    assert forces(first) is not forces(second)


def test_gains_validated_once_are_taken_as_given_and_checked_for_the_sizes():
    """scenario.builder.prepare_config validates the gains once into matrices; the controller takes those as
    they are (the same law as from the HybridGains) and refuses matrices of other sizes by name."""
    _, _, plant, robot, space = window_parts()
    gains = HybridGains(velocity=[10.0, 12.0], force_proportional=[0.5], force_integral=[15.0])
    validated = gains.matrices(space.velocity_size, space.force_size, "velocity-force", 1e-3)
    dut = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains=validated,
                           control_period=1e-3)
    twin = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains=gains,
                            control_period=1e-3)
    for name in ("velocity", "position", "force_proportional", "force_integral", "impedance_mass"):
        assert np.array_equal(getattr(dut.validated_gains(), name), getattr(twin.validated_gains(), name))
    other = HybridGains(velocity=[10.0], force_integral=[15.0]).matrices(1, 1, "velocity-force")
    with pytest.raises(ArgumentError, match="HybridController: gains are matrices for k = 1 velocity and m = 1 force "
                                            "rows; the constraint space has k = 2, m = 1"):
        HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains=other)
