"""The 6-DOF tasks on the UR5e: crank turning (Example 2.2 / 3-2) and sphere polishing (2.3 / 3-3)."""

import math

import numpy as np
import pytest
from run_checks import assert_rows_settled_within

from drake_hybrid import (BranchError, ChartSingularityError, EulerZXZChart, PoseChart, sphere_constraint,
                          sphere_paper_projection)
from drake_hybrid.analysis.discrete_linearization import linearize_discrete
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.core.kinematics import EndEffectorKinematics, inverse_kinematics
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.experiments.simulation import RunStopped, simulate
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import check_start, set_initial_conditions
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.tasks.builtin import crank_turning, sphere_polishing
from drake_hybrid.tasks.builtin.robots import UR5E_SEED, worst_condition_number
from drake_hybrid.tasks.registry import get_task

CRANK = get_task("crank-turning")
SPHERE = get_task("sphere-polishing")


@pytest.fixture(scope="module")
def crank_run():
    return simulate(CRANK.default_config())


@pytest.fixture(scope="module")
def sphere_run():
    return simulate(SPHERE.default_config())


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_crank_turns_at_the_commanded_rate_with_the_commanded_wrench(crank_run):
    summary, log = crank_run.summary, crank_run.log
    assert_rows_settled_within(summary, 2.0)
    assert summary.max_constraint_residual < 1e-3                   # the weld holds the handle
    assert max(summary.max_torque_to_effort_limit) < 1.0
    # The crank really turned: 0.5 rad/s for 3 s less the start transient.
    plant = crank_run.scenario.plant
    assert log["velocity"][-1][1] == pytest.approx(0.5, rel=0.02)
    assert summary.task == "crank-turning" and log["force"].shape[1] == 4


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_sphere_is_polished_along_the_latitude(sphere_run):
    summary, log = sphere_run.summary, sphere_run.log
    assert_rows_settled_within(summary, 2.0)
    assert summary.max_constraint_residual < 2e-3                  # the pad's compression, about 0.9 mm
    assert max(summary.max_torque_to_effort_limit) < 1.0
    # The orientation rows are held by the controller: a stays along -P to 1e-4 (rows of P x a, in m).
    assert np.abs(log["constraint"][len(log["t"]) // 5:, 1:]).max() < 1e-4


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_pole_crossing_fails_loudly_with_euler_angles_and_succeeds_with_the_pose_chart():
    config = SPHERE.default_config()
    config.task_options.update(path="pole", chart="euler")
    config.task_parameters["start_angle"] = 0.35          # the pole is 0.15 rad (0.5 s) ahead
    config.duration = 1.0
    with pytest.raises(RunStopped, match="ChartSingularityError.*(Euler|euler_zxz)") as stopped:
        simulate(config)
    assert isinstance(stopped.value.__cause__, ChartSingularityError)
    summary, log = stopped.value.result.summary, stopped.value.result.log
    assert summary.status == "error" and 0 < summary.stop_time < 1.0   # the log up to the stop is kept
    assert len(log["t"]) > 10 and log["t"][-1] <= summary.stop_time
    config.task_options["chart"] = "pose"
    config.duration = 1.5
    result = simulate(config)
    assert_rows_settled_within(result.summary, 2.0)
    # It did cross: the pad centre went over the top of the sphere (x passed the centre's x).
    positions = []
    plant = result.scenario.controller_plant
    context = plant.CreateDefaultContext()
    for q in result.log["q"][::100]:
        plant.SetPositions(context, q)
        positions.append(result.scenario.controller.kinematics.evaluate(context).position)
    x = np.array(positions)[:, 0] - sphere_polishing.SPHERE_CENTER[0]
    assert x[0] < -0.01 and x[-1] > 0.01


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_sphere_linearization_matches_the_design():
    result = linearize_continuous(SPHERE.default_config())
    assert result.equilibrium_residual < 1e-2
    assert result.match.matched, result.match.as_dict()
    assert np.all(result.match.relative_error < 0.05)


def test_crank_linearization_matches_the_design_up_to_the_handles_inertia():
    """The discrete closed loop's eigenvalues: all designed ones within 5 % except the spin row,
    which the handle's own spin inertia (not in the paper's massless constraint) slows to
    -K_v / (1 + M_p,spin I_handle)."""
    config = CRANK.default_config()
    result = linearize_discrete(config, settle_time=0.5)
    assert result.equilibrium_residual < 1e-4
    assert not np.any(result.match.unstable_extra)
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    plant_context = scenario.controller_plant.CreateDefaultContext()
    scenario.controller_plant.SetPositions(plant_context, CRANK.start_positions(scenario))
    task = scenario.controller.kinematics.evaluate(plant_context)
    values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
    M = scenario.controller_plant.CalcMassMatrix(plant_context)
    mobility = task.jacobian @ np.linalg.solve(M, task.jacobian.T)
    spin_mobility = (values.velocity_projection @ mobility @ values.velocity_projection.T)[0, 0]
    handle = scenario.plant.GetBodyByName("handle")
    spin_inertia = handle.default_rotational_inertia().get_moments()[2]
    corrected = -10.0 / (1.0 + spin_mobility * spin_inertia)
    errors = result.match.relative_error
    spin = np.argmin(np.abs(result.match.partner - corrected))
    assert abs(result.match.partner[spin] - corrected) < 0.02 * abs(corrected)
    assert np.all(np.delete(errors, spin) < 0.05)


@pytest.mark.parametrize("mode, impedance_mass", [("position-force", 1.0), ("impedance-force", 1.0),
                                                  ("impedance-force", 2.0)])
def test_crank_spin_pair_is_moved_by_the_handles_and_the_tools_inertia(mode, impedance_mass):
    """The spin row's designed pair s^2 + K_v s + K_p (-8, -2) in the two second-order modes.
    Position/force: the handle's inertia scales s^2 by (1 + M_p I_h), as in velocity mode.
    Impedance/force: the law feeds the measured F_v forward, and the wrist sensor (which removes the
    tool's weight, not its inertial force) also reports the tool's own spin inertia I_t, already in
    the controller's model: a = a_imp + (1 - M_p) F_meas + M_p F with F = -I_h a and
    F_meas = -(I_h + I_t) a gives (1 + I_h + I_t - M_p I_t) s^2 + K_v s + K_p, an 18 % lighter row.
    With an impedance mass M_d the feed-forward is (M_d^-1 - M_p) F_meas: (1 + M_d^-1 (I_h + I_t) - M_p I_t)."""
    config = CRANK.default_config().replace(mode=mode)
    config.gains.impedance_mass = [impedance_mass]
    assert isinstance(config.sensor, WristSensorConfig)
    scenario = build_scenario(config, with_loggers=False)
    plant_context = scenario.controller_plant.CreateDefaultContext()
    scenario.controller_plant.SetPositions(plant_context, CRANK.start_positions(scenario))
    task = scenario.controller.kinematics.evaluate(plant_context)
    values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
    M = scenario.controller_plant.CalcMassMatrix(plant_context)
    A = values.matrix @ task.jacobian @ np.linalg.solve(M, task.jacobian.T) @ values.matrix.T
    k = scenario.constraint_space.velocity_size
    mobility = A[:k, :k] - A[:k, k:] @ np.linalg.solve(A[k:, k:], A[k:, :k])   # constraint rows held
    spin_mobility = mobility[0, 0]
    I_h = scenario.plant.GetBodyByName("handle").default_rotational_inertia().get_moments()[2]
    I_t = scenario.plant.GetBodyByName("tool").default_rotational_inertia().get_moments()[2]
    K_v, K_p = config.gains.velocity[0], config.gains.position[0]
    factor = (1.0 + spin_mobility * I_h if mode == "position-force"
              else 1.0 + (I_h + I_t) / impedance_mass - spin_mobility * I_t)
    predicted = np.roots([factor, K_v, K_p])
    designed = np.roots([1.0, K_v, K_p])
    linearization = linearize_discrete(config, settle_time=0.5)
    eigenvalues = linearization.eigenvalues
    # the task's own prediction (CrankTurning.eigenvalue_shifts) is this one: the shifted design matches
    assert linearization.shifted_match is not None and linearization.shifted_match.matched
    for p, d in zip(predicted, designed):
        nearest = eigenvalues[np.argmin(np.abs(eigenvalues - p))]
        assert abs(nearest - p) < 0.02 * abs(p), (mode, impedance_mass, p, nearest)
    # ... and the prediction is a real correction: the pair is measurably off its design.
    assert max(abs(p - d) / abs(d) for p, d in zip(predicted, designed)) > 0.05


def test_naive_pseudo_velocity_tracks_worse_than_option_a():
    """docs/theory.md §6: the paper's pseudo-velocity with its unmeasurable Euler accelerations dropped
    (naive) against Option A: the true crank-rate error's deviation from the designed e^(-K_v t)."""
    deviations = {}
    for rows in ("true", "paper"):
        config = CRANK.default_config()
        config.task_options["velocity_rows"] = rows
        config.duration = 0.6
        result = simulate(config)
        scenario, log = result.scenario, result.log
        errors = crank_turning.true_velocities(scenario, log) - np.asarray(config.desired_velocity.value)
        designed = np.exp(-10.0 * log["t"])[:, None] * errors[0]
        deviations[rows] = np.abs(errors - designed).max()
    assert deviations["true"] < 0.01 * 0.5                            # Option A follows the design (< 1 %)
    assert deviations["paper"] > 3.0 * deviations["true"]              # measured: about 4.6 times worse


def test_wrist_sensor_reads_the_crank_constraint_wrench_at_rest():
    """No port reports the weld constraint's force, so infer it from the arm's static balance,
    J_g^T W = -(tau + tau_g), and compare the wrist sensor's reading (tool weight removed) with it."""
    from pydrake.systems.analysis import Simulator

    from drake_hybrid.systems.sources import Profile

    config = CRANK.default_config()
    config.desired_velocity = Profile(kind="constant", value=[0.0, 0.0])
    config.start.force_integral = []
    scenario = build_scenario(config, with_loggers=False)
    simulator = Simulator(scenario.diagram)
    context = simulator.get_mutable_context()
    set_initial_conditions(scenario, context)
    simulator.AdvanceTo(1.5)                                    # settle at rest
    plant, arm = scenario.plant, scenario.robot.arm
    plant_context = plant.GetMyContextFromRoot(context)
    assert np.abs(plant.GetVelocities(plant_context)).max() < 1e-6
    tau = plant.get_actuation_input_port(arm).Eval(plant_context)
    gravity = plant.CalcGravityGeneralizedForces(plant_context)
    J = scenario.kinematics.evaluate(plant_context).spatial_jacobian
    arm_columns = plant.GetVelocitiesFromArray(arm, np.arange(plant.num_velocities())).astype(int)
    inferred = -np.linalg.solve(J[:, arm_columns].T, tau + gravity[arm_columns])
    reading = scenario.sensor.get_output_port(0).Eval(scenario.sensor.GetMyContextFromRoot(context))
    np.testing.assert_allclose(reading, inferred, atol=1e-6 * np.linalg.norm(inferred))
    force = scenario.controller.GetOutputPort("force").Eval(scenario.controller.GetMyContextFromRoot(context))
    np.testing.assert_allclose(force, [0.0, 5.0, 0.0, 0.0], atol=1e-4)     # and the loop holds F_d


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_wrist_sensor_agrees_with_the_contact_sensor_on_the_sphere():
    from test_window_washing import sensor_readings_at_rest

    from_contact, from_wrist = sensor_readings_at_rest(SPHERE)
    # One SAP step from the (continuous-probe) pressing pose: about 9.95 N through the pad.
    assert np.linalg.norm(from_contact[3:]) > 9.0
    np.testing.assert_allclose(from_wrist, from_contact, atol=1e-6 * 10.0)


def test_corrected_3_3_13a_and_appendix_b_on_the_task_sphere(rng):
    """The paper's E_p (3.3-11, corrected 3.3-13a) is orthogonal to the (2.2-8) E_f on this sphere
    (centre c, radius 0.17 m); A is singular exactly at its poles and equator."""
    chart = EulerZXZChart()
    center, radius = sphere_polishing.SPHERE_CENTER, sphere_polishing.CONSTRAINT_RADIUS
    space = ConstraintSpace(sphere_constraint(chart, center=center, radius=radius, form="paper",
                                              dropped_component=3),
                            sphere_paper_projection(chart, center=center, radius=radius))
    for _ in range(20):
        phi, theta = rng.uniform(-3, 3), rng.uniform(0.3, 1.2) + rng.integers(0, 2) * 1.6
        a = np.array([math.sin(theta) * math.sin(phi), -math.sin(theta) * math.cos(phi), math.cos(theta)])
        r = np.r_[center - radius * a, phi, theta, rng.uniform(-3, 3)]
        values = space.evaluate(r, np.zeros(6))
        np.testing.assert_allclose(values.constraint_value, 0, atol=1e-14)
        np.testing.assert_allclose(values.force_projection @ values.velocity_projection.T, 0, atol=1e-12)
        A = values.force_projection[1:, 3:5]
        P = r[:3] - center
        assert np.linalg.det(A) == pytest.approx(-P[2] * math.sin(theta) * (P @ a), abs=1e-12)   # (B-2)
    equator = np.r_[center - radius * np.array([math.sin(0.4), -math.cos(0.4), 0.0]), 0.4, math.pi / 2, 0.0]
    with pytest.raises(Exception, match="loses rank|singular"):
        space.evaluate(equator, np.zeros(6))


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_outward_facing_starts_are_rejected():
    """Both the crank and the sphere constraints admit an outward branch (docs/theory.md §2); a start
    there is refused with a BranchError."""
    for task in (CRANK, SPHERE):
        config = task.default_config()
        scenario = build_scenario(config, with_loggers=False)
        plant = scenario.controller_plant
        context = plant.CreateDefaultContext()
        kinematics = EndEffectorKinematics(plant, "pad_center", np.zeros(3), PoseChart())
        seed = crank_turning.CRANK_SEED if task is CRANK else UR5E_SEED
        if task is CRANK:
            X = CRANK.handle_pose(crank_turning.START_ANGLE)
            from pydrake.math import RigidTransform, RotationMatrix

            # Same point on the circle, approach vector pointing away from the axis.
            X = RigidTransform(X.rotation().multiply(RotationMatrix.MakeXRotation(math.pi)), X.translation())
        else:
            from pydrake.math import RigidTransform, RotationMatrix
            X0 = SPHERE.pad_pose(config, 0.0)
            center = sphere_polishing.SPHERE_CENTER
            p = X0.translation()
            # The mirror point through the centre with the same orientation: a points away from it.
            X = RigidTransform(X0.rotation(), 2 * center - p)
        q = inverse_kinematics(kinematics, context, X, seed)
        with pytest.raises(BranchError, match="wrong branch"):
            check_start(scenario, q)


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
@pytest.mark.parametrize("task", [CRANK, SPHERE], ids=lambda t: t.name)
def test_tasks_stay_away_from_kinematic_singularities(task):
    """The worst condition number of the geometric Jacobian along the run (reported in the docs)."""
    config = task.default_config()
    config.duration = 1.0
    result = simulate(config)
    plant = result.scenario.controller_plant
    worst = worst_condition_number(result.scenario.controller.kinematics, plant, result.log["q"][::20])
    assert worst < 100
