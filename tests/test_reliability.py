"""Fault injection: contact loss and re-acquisition, sensor faults, model error, actuator limits,
singularities and bad configuration, each with a pass criterion on a measured figure.

The closed-loop cases are those of ``drake_hybrid.reliability`` (docs/reliability.py runs them with
longer horizons and writes the table of docs/results.md); the unit tests below check the pieces against
their definitions: the supervisor's transitions, the conditioner and the injector sample by
sample, the guarded move and the saturation against the plant's dynamics, the damped inverse.
"""

import math
import warnings

import numpy as np
import pytest
import reliability_cases as reliability

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid import ChartSingularityError
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.safety import SafetyConfig, bounded_solve, bounded_task_inertia, saturate, saturation_scale
from drake_hybrid.control.supervision import ContactSupervisor, SupervisionConfig
from drake_hybrid.core.errors import KinematicSingularityWarning
from drake_hybrid.core.linalg import value
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.systems.faults import SensorFaultConfig, SensorFaultInjector
from drake_hybrid.systems.wrench_conditioner import WrenchConditioner
from drake_hybrid.tasks.plant import build_controller_plant
from drake_hybrid.tasks.registry import get_task

WINDOW = get_task("window-washing")


# ------------------------------------------------------------------------------------------------
# The fault cases (closed loop, measured figures)
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("case", [case for case in reliability.CASES if case is not reliability.case_bad_configuration],
                         ids=lambda case: case.__name__[len("case_"):])
@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_fault_case_meets_its_criteria(case):
    figures = case(quick=True)
    assert figures
    _, new_failures, fixed = reliability.split_failures(figures)
    assert not new_failures, [figure.row() for figure in new_failures]
    # A known failure is kept visible: it must still fail.
    assert not fixed, ([figure.row() for figure in fixed], "passes now: remove it from KNOWN_FAILURES")
    for figure in figures:
        assert math.isfinite(figure.value), figure.row()


def test_known_failures_are_reported_as_known_and_only_a_new_failure_exits_nonzero():
    """docs/reliability.py's verdict: a failed row KNOWN_FAILURES lists is "FAIL (known)" and exits 0; any
    other failed row is a regression ("FAIL", exit 1); a listed row that passes now is reported, exit 0."""
    def figure(fault, passed):
        return reliability.Figure("case", fault, "1 unit", "error", 1.0, 2.0, "", "<= 2", passed)

    known = {("drifts", "1 unit", "error"): "why it fails"}
    drifts, breaks, holds, reference = (figure("drifts", False), figure("breaks", False), figure("holds", True),
                                        figure("compare", None))
    assert reliability.exit_code([drifts, holds, reference], known) == 0
    assert reliability.exit_code([drifts, breaks, holds], known) == 1
    assert reliability.exit_code([breaks], {}) == 1
    assert reliability.exit_code([figure("drifts", True), holds], known) == 0
    assert reliability.split_failures([drifts, breaks, holds, reference], known) == ([drifts], [breaks], [])
    assert reliability.split_failures([figure("drifts", True)], known)[2][0].fault == "drifts"
    # The table says which: the listed row of KNOWN_FAILURES itself.
    listed = reliability.Figure("case", *next(iter(reliability.KNOWN_FAILURES)), 1.0, 0.5, "", "", False)
    assert listed.row()[-1] == "FAIL (known)" and breaks.row()[-1] == "FAIL" and reference.row()[-1] == "reference"


@pytest.mark.parametrize("bad", reliability.BAD_CONFIGURATIONS, ids=lambda bad: bad.description)
def test_bad_configuration_is_rejected_with_a_clear_message(bad):
    with pytest.raises(bad.error, match=bad.match):
        bad.call()


def test_start_off_the_surface_approaches_instead_of_raising():
    config = WINDOW.default_config()
    config.start.in_contact = False
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    assert scenario.supervisor is not None
    phase = scenario.supervisor.GetOutputPort("contact_phase").Eval(scenario.supervisor.GetMyContextFromRoot(context))
    assert ContactPhase(int(phase[0])) is ContactPhase.APPROACH
    # The pad starts start.gap below the window, and the held torque is gravity only (no push).
    C = scenario.controller.GetOutputPort("constraint_value").Eval(scenario.controller.GetMyContextFromRoot(context))
    assert C[0] == pytest.approx(-config.start.gap, abs=1e-9)


# ------------------------------------------------------------------------------------------------
# Contact supervisor
# ------------------------------------------------------------------------------------------------

def supervisor(**changes):
    return ContactSupervisor(SupervisionConfig(**changes), 1, (), 1e-3)


def step(dut, state, force, constraint=0.0, valid=True, steps=1):
    for _ in range(steps):
        state = dut.next_state(state, np.array([force]), np.array([-10.0]), np.array([constraint]), valid)
    return state


def test_supervisor_declares_contact_at_the_threshold_and_loss_after_the_dwell():
    dut = supervisor(contact_threshold=0.3, loss_threshold=0.1, loss_dwell=0.01)
    approach = np.array([float(ContactPhase.APPROACH), 0.0, 0.0, -0.01, -0.01])
    assert step(dut, approach, -2.9)[0] == ContactPhase.APPROACH           # p = 2.9 N < 3 N
    contact = step(dut, approach, -3.0)
    assert contact[0] == ContactPhase.CONTACT and contact[2] == 1          # one contact made
    assert step(dut, contact, -0.5, steps=9)[0] == ContactPhase.CONTACT     # 9 ms below 1 N: not yet
    lost = step(dut, contact, -0.5, constraint=0.004, steps=10)
    assert lost[0] == ContactPhase.APPROACH and lost[3] == pytest.approx(0.004)   # C_entry recorded
    assert lost[4] == pytest.approx(0.004)                                        # C_r reset to C
    # A force back above the loss threshold resets the dwell timer.
    interrupted = step(dut, step(dut, contact, -0.5, steps=9), -5.0)
    assert step(dut, interrupted, -0.5, steps=9)[0] == ContactPhase.CONTACT


def test_supervisor_makes_no_decision_on_an_invalid_wrench():
    dut = supervisor()
    contact = np.array([float(ContactPhase.CONTACT), 0.0, 1.0, 0.0, 0.0])
    assert np.array_equal(step(dut, contact, 0.0, valid=False, steps=100), contact)
    approach = np.array([float(ContactPhase.APPROACH), 0.0, 0.0, 0.0, 0.0])
    assert step(dut, approach, -10.0, valid=False)[0] == ContactPhase.APPROACH


def test_supervisor_holds_after_the_allowed_travel_and_tares_first():
    dut = supervisor(max_travel=0.01, tare_time=0.05)
    approach = np.array([float(ContactPhase.APPROACH), 0.0, 0.0, -0.03, -0.03])
    assert step(dut, approach, 0.0, constraint=-0.0205)[0] == ContactPhase.APPROACH   # 9.5 mm travelled
    hold = step(dut, approach, 0.0, constraint=-0.0195)
    assert hold[0] == ContactPhase.HOLD
    assert step(dut, hold, -4.0)[0] == ContactPhase.CONTACT                          # the surface came to us
    tare = np.array([float(ContactPhase.TARE), 0.0, 0.0, 0.0, 0.0])
    assert step(dut, tare, 0.0, steps=49)[0] == ContactPhase.TARE
    assert step(dut, tare, 0.0, constraint=-0.01, steps=50)[0] == ContactPhase.APPROACH


def test_supervisor_reference_moves_at_the_approach_speed_in_approach_only():
    """C_r: C when APPROACH begins, then + h s n_C per period (n_C = +1 for F_d = -10 N), standing in HOLD
    and CONTACT: C - C_r is the integral of the guarded move's velocity error since APPROACH began."""
    dut = supervisor(approach_speed=0.02, max_travel=0.01)
    tare = np.array([float(ContactPhase.TARE), 0.0, 0.0, 0.0, 0.0])
    entered = step(dut, tare, 0.0, constraint=-0.01)                           # tare_time 0: APPROACH now
    assert entered[0] == ContactPhase.APPROACH and entered[4] == pytest.approx(-0.01)
    moving = step(dut, entered, 0.0, constraint=-0.01, steps=100)                # the arm stays put
    assert moving[0] == ContactPhase.APPROACH and moving[4] == pytest.approx(-0.01 + 100 * 1e-3 * 0.02)
    hold = step(dut, moving, 0.0, constraint=0.0005)                              # 10.5 mm travelled
    assert hold[0] == ContactPhase.HOLD and hold[4] == moving[4]
    assert step(dut, hold, 0.0, steps=50)[4] == moving[4]                         # standing in HOLD
    contact = step(dut, moving, -3.0, constraint=-0.009)
    assert contact[0] == ContactPhase.CONTACT and contact[4] == moving[4]


def test_supervisor_reference_stands_on_an_invalid_wrench_and_stops_at_the_travel_bound():
    """Blocked short of the threshold (the arm does not move, the sensor reads nothing), C_r stops at
    max_travel + 2 s / K_a from C_entry, so the guarded move's push is bounded; with an invalid wrench
    it does not move at all."""
    dut = supervisor(approach_speed=0.02, approach_gain=30.0, max_travel=0.01)
    approach = np.array([float(ContactPhase.APPROACH), 0.0, 0.0, -0.01, -0.01])
    assert np.array_equal(step(dut, approach, 0.0, constraint=-0.01, valid=False, steps=50), approach)
    blocked = step(dut, approach, 0.0, constraint=-0.01, steps=2000)          # 2 s at 2 cm/s: 40 mm asked
    assert blocked[0] == ContactPhase.APPROACH                                  # the arm never travelled
    assert blocked[4] == pytest.approx(-0.01 + 0.01 + 2 * 0.02 / 30.0)          # C_r: 11.33 mm, no further


# ------------------------------------------------------------------------------------------------
# Wrench conditioner and fault injector
# ------------------------------------------------------------------------------------------------

def tick(dut, context, raw, sequence=None, phase=None):
    """One sample: fix the inputs, read the output, advance the state."""
    dut.GetInputPort("raw_wrench").FixValue(context, raw)
    if sequence is not None:
        dut.GetInputPort("sequence").FixValue(context, [sequence])
    if phase is not None:
        dut.GetInputPort("contact_phase").FixValue(context, [float(phase)])
    output = dut.GetOutputPort("wrench").Eval(context).copy()
    context.SetDiscreteState(0, dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value())
    return output


def test_conditioner_holds_a_dropout_for_max_hold_time_then_reports_nan():
    dut = WrenchConditioner(period=1e-3, max_hold_time=3e-3)
    context = dut.CreateDefaultContext()
    good = np.array([0, 0, 0, 0, 0, -10.0])
    dut.set_initial_output(context, good)
    nan = np.full(6, np.nan)
    outputs = [tick(dut, context, nan) for _ in range(4)]
    for held in outputs[:3]:
        np.testing.assert_array_equal(held, good)                  # held for 3 samples (3 ms)
    assert np.all(np.isnan(outputs[3]))                           # then invalid
    np.testing.assert_array_equal(tick(dut, context, good * 1.1), good * 1.1)   # a fresh sample: valid at once


def test_conditioner_rejects_stale_samples_by_sequence_number_and_tares():
    dut = WrenchConditioner(period=1e-3, max_hold_time=1e-3, use_sequence=True, tare=True)
    context = dut.CreateDefaultContext()
    dut.set_initial_output(context, np.zeros(6), sequence=0.0)
    bias = np.array([0.1, 0, 0, 0.2, 0, 1.0])
    for k in range(1, 11):                                          # ten fresh samples in TARE
        tick(dut, context, bias + 0.01 * (k - 5.5), sequence=k, phase=ContactPhase.TARE)
    reading = bias + np.array([0, 0, 0, 0, 0, -10.0])
    np.testing.assert_allclose(tick(dut, context, reading, sequence=11, phase=ContactPhase.CONTACT),
                               [0, 0, 0, 0, 0, -10.0], atol=1e-12)              # the tare is the mean
    np.testing.assert_allclose(tick(dut, context, reading, sequence=11, phase=ContactPhase.CONTACT),
                               [0, 0, 0, 0, 0, -10.0], atol=1e-12)              # stale: held one sample
    assert np.all(np.isnan(tick(dut, context, reading, sequence=11, phase=ContactPhase.CONTACT)))


def test_conditioner_low_pass_is_the_exact_discretization():
    dut = WrenchConditioner(period=1e-3, bandwidth_hz=50.0)
    context = dut.CreateDefaultContext()
    dut.set_initial_output(context, np.zeros(6))
    step_input = np.ones(6)
    outputs = np.array([tick(dut, context, step_input)[0] for _ in range(20)])
    k = np.arange(1, 21)
    np.testing.assert_allclose(outputs, 1 - np.exp(-2 * np.pi * 50.0 * 1e-3 * k), rtol=1e-12)


def test_injector_samples_are_deterministic_and_have_the_configured_statistics():
    config = SensorFaultConfig(noise_std=0.5, torque_noise_std=0.01, bias=[0, 0, 0, 0, 0, 1.0], seed=7,
                               dropout_times=[0.0105], dropout_duration=0.003, dropout_kind="stale")
    dut = SensorFaultInjector(config, 1e-3)
    noise = np.array([dut.noise(k) for k in range(20000)])
    assert noise[:, 3:].std() == pytest.approx(0.5, rel=0.02)
    assert noise[:, :3].std() == pytest.approx(0.01, rel=0.02)
    np.testing.assert_array_equal(SensorFaultInjector(config, 1e-3).noise(12345), dut.noise(12345))   # the seed
    assert [k for k in range(20) if dut.dropped(k)] == [11, 12, 13]                  # 10.5 ms for 3 ms
    # Sample k is the same whenever it is read between the plant steps at k h and (k + 1) h.
    context = dut.CreateDefaultContext()
    dut.GetInputPort("wrench").FixValue(context, np.zeros(6))
    readings = []
    for t in (0.005, 0.005 + 0.999e-3):
        context.SetTime(t)
        readings.append(dut.GetOutputPort("faulty_wrench").Eval(context).copy())
    np.testing.assert_array_equal(readings[0], readings[1])
    np.testing.assert_allclose(readings[0], config.bias + dut.noise(5))
    # A stale sample repeats the last emitted one and does not advance the sequence.
    context.SetTime(0.0115)                                           # sample 11: stale
    last = context.get_discrete_state(0).CopyToVector()
    np.testing.assert_array_equal(dut.GetOutputPort("faulty_wrench").Eval(context), last[:6])
    assert dut.GetOutputPort("sequence").Eval(context)[0] == last[6]


def test_random_dropouts_lose_the_expected_fraction_of_samples():
    dut = SensorFaultInjector(SensorFaultConfig(dropout_probability=0.02, dropout_samples=5, seed=2), 1e-3)
    lost = np.mean([dut.dropped(k) for k in range(20000)])
    assert lost == pytest.approx(1 - (1 - 0.02) ** 5, abs=0.01)       # 9.6 % of the samples


# ------------------------------------------------------------------------------------------------
# Controller: guarded move, saturation and anti-windup, singularities, scalar types
# ------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def window_parts():
    config = WINDOW.default_config()
    plant, robot = build_controller_plant(WINDOW, config)
    return plant, robot, WINDOW.constraint_space(config)


def controller(window_parts, **arguments):
    plant, robot, space = window_parts
    gains = HybridGains(velocity=[10.0, 8.0], force_proportional=0.5, force_integral=15.0)
    return HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, gains,
                            control_period=1e-3, **arguments)


def fix(dut, context, q, v, wrench=np.zeros(6), phase=None, desired_force=-10.0, reference=0.0):
    dut.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, v]))
    dut.GetInputPort("measured_wrench").FixValue(context, wrench)
    dut.GetInputPort("desired_velocity").FixValue(context, [0.1, 0.0])
    dut.GetInputPort("desired_acceleration").FixValue(context, [0.0, 0.0])
    dut.GetInputPort("desired_force").FixValue(context, [desired_force])
    if phase is not None:
        dut.GetInputPort("contact_phase").FixValue(context, [float(phase)])
        dut.GetInputPort("approach_reference").FixValue(context, [reference])


@pytest.mark.parametrize("phase", [ContactPhase.APPROACH, ContactPhase.HOLD, ContactPhase.TARE])
def test_guarded_move_produces_its_constraint_acceleration_in_free_space(window_parts, phase, rng):
    """Off the surface, the torque makes C-ddot = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r) and the
    velocity rows' designed acceleration, checked with the plant's forward dynamics; xi does not integrate."""
    plant, robot, space = window_parts
    supervision = SupervisionConfig(approach_speed=0.02, approach_gain=30.0)
    dut = controller(window_parts, guarded_move=supervision)
    context = dut.CreateDefaultContext()
    context.SetDiscreteState(0, np.array([0.3, 0.0, 0.0, 0.0]))
    q = WINDOW.inverse_kinematics(WINDOW.default_config(), 0.9, 0.97, 1.5)
    v = rng.normal(size=3) * 0.2
    fix(dut, context, q, v, phase=phase, reference=0.004)
    update = dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value()
    tau, xi = update[1:], update[0]
    assert xi == 0.3                                                    # frozen off the surface
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    plant.SetVelocities(plant_context, v)
    M = plant.CalcMassMatrix(plant_context)
    bias = plant.CalcBiasTerm(plant_context) - plant.CalcGravityGeneralizedForces(plant_context)
    q_ddot = np.linalg.solve(M, tau - bias)
    task = dut.kinematics.evaluate(plant_context)
    values = space.evaluate(task.configuration, task.velocity)
    r_ddot = task.jacobian @ q_ddot + task.bias
    C_dot = values.force_projection @ task.velocity
    speed = 0.02 if phase is ContactPhase.APPROACH else 0.0
    C = values.constraint_value
    np.testing.assert_allclose(values.force_projection @ r_ddot + values.force_curvature,
                               -60.0 * (C_dot - speed * 1.0) - 900.0 * (C - 0.004), atol=1e-9)  # n_C = +1: up
    velocity_error = values.velocity_projection @ task.velocity - [0.1, 0.0]
    np.testing.assert_allclose(values.velocity_projection @ r_ddot + values.velocity_curvature,
                               -np.diag([10.0, 8.0]) @ velocity_error, atol=1e-9)


def test_saturation_scales_the_task_part_and_freezes_the_integral(window_parts, rng):
    plant, robot, space = window_parts
    limits = [45.0, 80.0, 30.0]                  # joint 1: gravity needs 30 N m, pressing with 40 N about 66
    q = WINDOW.inverse_kinematics(WINDOW.default_config(), 0.9, 0.98, math.pi / 2)
    v = np.zeros(3)
    results = {}
    for anti_windup in (True, False):
        dut = controller(window_parts, safety=SafetyConfig(effort_limits=limits, anti_windup=anti_windup))
        context = dut.CreateDefaultContext()
        context.SetDiscreteState(0, np.array([0.3, 0.0, 0.0, 0.0]))
        fix(dut, context, q, v, wrench=np.array([0, 0, 0, 0, 0, -4.0]), desired_force=-40.0)
        results[anti_windup] = (dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value(),
                                dut.diagnostics(context))
    update, diagnostics = results[True]
    assert 0 < diagnostics["saturation_scale"] < 1 and not diagnostics["actuator_clipped"]
    assert np.all(np.abs(update[1:]) <= np.array(limits) + 1e-9)
    assert np.isclose(np.abs(update[1:]), limits).any()                # one actuator exactly at its limit
    assert update[0] == 0.3                                              # xi frozen while saturated
    assert results[False][0][0] == pytest.approx(0.3 + 1e-3 * (-4.0 + 40.0))   # without: xi += h e_f
    # Graceful: the saturated torque is g + s (tau - g), on the line from the gravity torque.
    unsaturated = controller(window_parts)
    context = unsaturated.CreateDefaultContext()
    context.SetDiscreteState(0, np.array([0.3, 0.0, 0.0, 0.0]))
    fix(unsaturated, context, q, v, wrench=np.array([0, 0, 0, 0, 0, -4.0]), desired_force=-40.0)
    full = unsaturated.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value()[1:]
    plant_context = plant.CreateDefaultContext()
    plant.SetPositions(plant_context, q)
    gravity = -plant.CalcGravityGeneralizedForces(plant_context)
    np.testing.assert_allclose(update[1:], gravity + diagnostics["saturation_scale"] * (full - gravity), atol=1e-9)


def test_saturation_helpers():
    assert saturation_scale([1.0, 0.0], [4.0, -1.0], [3.0, 3.0]) == pytest.approx(0.5)
    assert saturation_scale([4.0, 0.0], [1.0, 1.0], [3.0, 3.0]) == 0.0           # base beyond its limit
    seeded = np.array([AutoDiffXd(5.0, [1.0, 0.0]), AutoDiffXd(1.0, [0.0, 1.0])], dtype=object)
    saturated, scale, clipped = saturate(seeded, lambda: np.array([AutoDiffXd(4.0, [1.0, 0.0]),
                                                                  AutoDiffXd(0.0, [0.0, 0.0])], dtype=object),
                                         np.array([3.0, 3.0]))
    assert scale == 0.0 and clipped
    assert value(saturated).tolist() == [3.0, 0.0]
    assert not np.any(saturated[0].derivatives())                               # beyond the limit: constant
    assert saturated[1].derivatives().tolist() == [0.0, 0.0]                    # base + 0 (task): base's


def test_bounded_inverse_is_exact_within_the_bound_and_the_trust_region_solution_beyond():
    rhs = np.array([1.0, 1.0, 1.0])
    near = np.diag([1.0, 0.5, 0.03])                                      # |J^-1 rhs| = 33.4
    far = bounded_solve(near, rhs, threshold=0.01, max_norm=10.0)         # not "near": exact beyond the bound
    assert far[2] == 0.0 and np.array_equal(far[0], np.linalg.solve(near, rhs))
    exact, sigma, damping = bounded_solve(near, rhs, threshold=0.05, max_norm=50.0)
    assert damping == 0.0 and np.array_equal(exact, np.linalg.solve(near, rhs))
    bounded, sigma, damping = bounded_solve(near, rhs, threshold=0.05, max_norm=10.0)
    assert damping > 0 and np.linalg.norm(bounded) == pytest.approx(10.0, rel=1e-9)
    # It is the least-squares solution damped by lambda^2: (J^T J + lambda^2 I) x = J^T rhs.
    np.testing.assert_allclose((near.T @ near + damping * np.eye(3)) @ bounded, near.T @ rhs, atol=1e-9)
    singular = np.diag([1.0, 0.5, 0.0])                                   # no exact solution at all
    solution, sigma, damping = bounded_solve(singular, rhs, threshold=0.05, max_norm=10.0)
    assert sigma == 0.0 and np.all(np.isfinite(solution)) and solution[2] == 0.0
    np.testing.assert_allclose(solution[:2], [1.0, 2.0], rtol=1e-6)       # the reachable part, nearly exact
    # The redundant version bounds M^-1 J^T Lambda rhs the same way.
    J = np.array([[1.0, 0.0, 0.3], [0.0, 0.02, 0.0]])
    M_inverse = np.diag([1.0, 2.0, 4.0])
    mobility = J @ M_inverse @ J.T
    Lambda, sigma, mu = bounded_task_inertia(J, M_inverse, mobility, np.array([0.0, 1.0]), 0.05, max_norm=10.0)
    assert mu > 0 and np.linalg.norm(M_inverse @ J.T @ Lambda @ [0.0, 1.0]) == pytest.approx(10.0, rel=1e-6)
    Lambda, sigma, mu = bounded_task_inertia(J, M_inverse, mobility, np.array([0.0, 1.0]), 0.05, max_norm=100.0)
    assert mu == 0.0 and np.allclose(Lambda, np.linalg.inv(mobility))


def test_controller_at_an_exact_singularity_warns_and_stays_finite(window_parts):
    """The 3R arm stretched (q2 = 0): J loses rank, and a command along the lost direction cannot be
    produced. Without a bound the torque is huge (or the solve fails); bounded it is finite and the
    controller warns. (Effort limits lifted so that saturation does not hide the difference.)"""
    stretched = np.array([0.3, 1e-7, 1.2])
    torques = {}
    for bound in (1e12, 50.0):
        dut = controller(window_parts, safety=SafetyConfig(effort_limits=[1e12] * 3, max_joint_acceleration=bound))
        context = dut.CreateDefaultContext()
        fix(dut, context, stretched, np.array([0.1, -0.1, 0.0]), wrench=np.array([0, 0, 0, 0, 0, -10.0]))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            torques[bound] = dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value()[1:]
        warned = [w for w in caught if issubclass(w.category, KinematicSingularityWarning)]
        assert bool(warned) == (bound == 50.0)
    assert np.max(np.abs(torques[1e12])) > 1e4
    assert np.all(np.isfinite(torques[50.0])) and np.max(np.abs(torques[50.0])) < 200.0


def test_non_finite_state_raises_and_autodiff_instance_matches(window_parts):
    dut = controller(window_parts, guarded_move=SupervisionConfig())
    context = dut.CreateDefaultContext()
    q = WINDOW.inverse_kinematics(WINDOW.default_config(), 0.9, 0.98, math.pi / 2)
    fix(dut, context, np.array([np.nan, q[1], q[2]]), np.zeros(3), phase=ContactPhase.APPROACH)
    with pytest.raises(ValueError, match="input 'estimated_state' has non-finite entries"):
        dut.GetOutputPort("force_error").Eval(context)
    fix(dut, context, q, np.zeros(3), phase=7)
    with pytest.raises(ValueError, match="contact_phase must be one of"):
        dut.GetOutputPort("force_error").Eval(context)
    dut_ad = dut.ToAutoDiffXd()
    context_ad = dut_ad.CreateDefaultContext()
    for system, ctx in ((dut, context), (dut_ad, context_ad)):
        fix(system, ctx, q, np.array([0.1, 0.0, -0.1]), phase=ContactPhase.APPROACH)
    np.testing.assert_allclose(value(dut_ad.EvalUniquePeriodicDiscreteUpdate(context_ad).get_vector(0).CopyToVector()),
                               dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value(), atol=1e-10)
    for system in (ContactSupervisor(SupervisionConfig(), 1, (), 1e-3), WrenchConditioner(1e-3, tare=True),
                   SensorFaultInjector(SensorFaultConfig(noise_std=0.1), 1e-3)):
        assert system.ToAutoDiffXd() is not None


# ------------------------------------------------------------------------------------------------
# 6-DOF: the UR5e near a wrist singularity and at the Euler chart's singularity
# ------------------------------------------------------------------------------------------------

def test_ur5e_wrist_singularity_is_damped_and_the_euler_pole_raises_the_typed_error():
    task = get_task("sphere-polishing")
    config = task.default_config()
    plant, robot = build_controller_plant(task, config)
    wrist_singular = np.array([0.0, -1.9, 1.9, -1.6, 0.0, 0.0])     # q5 = 0: wrist axes 4 and 6 aligned
    pointing_down = np.array([0.0, -1.6, 1.6, -1.57, -1.5708, 0.0])  # approach along -z: Euler theta = pi
    for chart, q, expected in (("pose", wrist_singular, None), ("euler", pointing_down, ChartSingularityError)):
        config.task_options["chart"] = chart
        space = task.constraint_space(config)
        dut = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space, config.gains,
                               control_period=1e-3)
        context = dut.CreateDefaultContext()
        dut.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, np.zeros(6)]))
        dut.GetInputPort("measured_wrench").FixValue(context, np.zeros(6))
        dut.GetInputPort("desired_velocity").FixValue(context, np.zeros(3))
        dut.GetInputPort("desired_acceleration").FixValue(context, np.zeros(3))
        dut.GetInputPort("desired_force").FixValue(context, [10.0, 0.0, 0.0])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            if expected is not None:
                with pytest.raises(expected, match="singular"):
                    dut.EvalUniquePeriodicDiscreteUpdate(context)
                continue
            update = dut.EvalUniquePeriodicDiscreteUpdate(context).get_vector(0).value()
        assert any(issubclass(w.category, KinematicSingularityWarning) for w in caught)
        assert dut.diagnostics(context)["smallest_singular_value"] < 1e-6
        torque = update[-6:]
        assert np.all(np.isfinite(torque)) and np.all(np.abs(torque) <= dut.effort_limits)
