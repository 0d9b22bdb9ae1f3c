"""Issue 18: the baselines, the Raibert-Craig kinematic instability, and the crank's design held.

Fast tests (about 15 s) check the instability against its analytic prediction, the map, the
systems' ports, scalar types and bad inputs, and the crank's eigenvalues in all three modes; the
window comparison (the table's script) is marked slow.
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from drake_hybrid.analysis import kinematic_instability as ki
from drake_hybrid.analysis.discrete_linearization import linearize_discrete
from drake_hybrid.control.baselines import (AxisPDOpenLoopForceController, BaselineGains, JointServoHybridController,
                                            joint_servo_eigenvalues, make_baseline)
from drake_hybrid.core.errors import ConfigError, DimensionError
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.tasks.config import MechanismConfig, load_config
from drake_hybrid.tasks.registry import get_task

CRANK = get_task("crank-turning")
DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture(scope="module")
def raibert_craig():
    loop = ki.build_two_link_loop("raibert-craig")
    eigenvalues, A = ki.linearized_eigenvalues(loop)
    return loop, eigenvalues, A


def test_raibert_craig_is_unstable_at_the_hinted_configuration(raibert_craig):
    """Drake's Linearize of the whole loop (plant and controller in AutoDiffXd) has the right-half-plane
    root of s^2 + K_s s + K_s mu that the first-order model predicts, mu = e_x^T J K_q J^-1 e_x < 0."""
    _, eigenvalues, _ = raibert_craig
    analytic = ki.analytic_eigenvalues("raibert-craig")
    worst = eigenvalues.real.max()
    assert worst > 1.0
    assert worst == pytest.approx(analytic.real.max(), rel=1e-6)
    # every analytic root has a partner in the linearization (the rest are zeros: e_p - E_p J q, xi)
    for root in analytic:
        assert np.min(np.abs(eigenvalues - root)) < 1e-6 * max(1.0, abs(root))


def test_raibert_craig_grows_at_the_predicted_rate_in_simulation(raibert_craig):
    loop, _, A = raibert_craig
    growth, predicted = ki.simulated_growth_rate(loop, A)
    assert predicted > 1.0
    assert abs(growth - predicted) < 0.10 * predicted


@pytest.mark.parametrize("controller", ["fisher-mujtaba", "li-sastry", "pd-open-loop-force"])
def test_same_task_is_stable_with_fisher_mujtaba_li_sastry_and_the_pd(controller):
    eigenvalues, _ = ki.linearized_eigenvalues(ki.build_two_link_loop(controller))
    assert eigenvalues.real.max() < 1e-9
    # Nonzero eigenvalues are the predicted ones: same gains (FM), same bandwidth (LS: -1, -5), and the
    # PD with K = K_p, D = K_v scaled by the row's task inertia: the same design on the free row.
    analytic = ki.analytic_eigenvalues(controller)
    for root in analytic[np.abs(analytic) > 1e-9]:
        assert np.min(np.abs(eigenvalues - root)) < 1e-6 * abs(root)
    if controller != "fisher-mujtaba":
        assert sorted(analytic.real) == pytest.approx([-5.0, -1.0])


def test_stability_map_raibert_craig_unstable_somewhere_fisher_mujtaba_nowhere():
    q = np.linspace(-np.pi, np.pi, 25)
    maps = ki.stability_map(q, q)
    regular = np.isfinite(maps["raibert-craig"])
    assert 0.02 < np.mean(maps["raibert-craig"][regular] > 0) < 0.5
    assert np.nanmax(maps["fisher-mujtaba"]) < 0
    # Equal joint gains: J^-1 S J is a projection, so Raibert-Craig is stable everywhere.
    equal = ki.stability_map(q, q, joint_gains=(3.0, 3.0))
    assert np.nanmax(equal["raibert-craig"]) < 0


def test_map_agrees_with_drake_at_sampled_configurations():
    for q in (np.radians([-160.0, 30.0]), np.radians([40.0, 70.0]), np.radians([120.0, -100.0])):
        worst = ki.stability_map([q[0]], [q[1]])
        for name in ("raibert-craig", "fisher-mujtaba"):
            eigenvalues, _ = ki.linearized_eigenvalues(ki.build_two_link_loop(name, q0=q))
            nonzero = eigenvalues[np.abs(eigenvalues) > 1e-8]           # the zeros: e_p - E_p J q, xi
            assert nonzero.real.max() == pytest.approx(worst[name][0, 0], abs=1e-6), (name, q)


def test_joint_servo_eigenvalues_of_the_pseudoinverse_are_stable_for_any_positive_gains():
    rng = np.random.default_rng(18)
    for _ in range(50):
        J = rng.normal(size=(2, 2))
        gains = rng.uniform(0.1, 10.0, size=2)
        mu, roots = joint_servo_eigenvalues(J, np.array([[1.0, 0.0]]), np.eye(2), gains, 100.0, "pseudoinverse")
        assert np.all(mu.real > -1e-9) and np.all(roots.real < 1e-9)


def window_scenario(controller):
    config = get_task("window-washing").default_config().replace(controller=controller, mode="position-force")
    return build_scenario(config, with_loggers=False)


@pytest.mark.parametrize("controller", ["raibert-craig", "fisher-mujtaba", "pd-open-loop-force"])
def test_baselines_have_the_controller_ports_and_convert_scalars(controller):
    scenario = window_scenario(controller)
    dut = scenario.controller
    n, k, m = 3, 2, 1
    sizes = {"estimated_state": 2 * n, "measured_wrench": 6, "desired_velocity": k, "desired_acceleration": k,
             "desired_force": m}
    assert {dut.get_input_port(i).get_name(): dut.get_input_port(i).size()
            for i in range(dut.num_input_ports())} == sizes
    outputs = {dut.get_output_port(i).get_name(): dut.get_output_port(i).size() for i in range(dut.num_output_ports())}
    assert outputs == {"actuation": n, "velocity_error": k, "force_error": m, "constraint_value": m,
                       "projected_velocity": k, "force": m, "tangential_force": k, "wrench_valid": 1, "position_error": k}
    converted = dut.ToAutoDiffXd()
    assert converted.num_output_ports() == dut.num_output_ports()


def test_bad_inputs_name_the_field():
    config = get_task("window-washing").default_config()
    with pytest.raises(ConfigError, match="controller must be one of"):
        config.replace(controller="pid").validate()
    with pytest.raises(ConfigError, match="mechanism.source must be one of"):
        MechanismConfig(source="guess").validate()
    with pytest.raises(ConfigError, match="mechanism.velocity_row_inertia must have"):
        MechanismConfig(source="given").validate()
    with pytest.raises(ConfigError, match="baseline.servo_rate must be positive"):
        BaselineGains(servo_rate=0.0).validate()
    with pytest.raises(ConfigError, match="baseline.joint_gains"):
        BaselineGains(joint_gains=[-1.0]).validate()
    with pytest.raises(ConfigError, match="mechanism.source: task 'window-washing' has no mechanism"):
        build_scenario(config.replace(mechanism=MechanismConfig(source="plant")), with_loggers=False)
    with pytest.raises(ConfigError, match="unknown|controller"):
        load_config(data="controller: [1]")
    scenario = window_scenario("raibert-craig")
    plant, space = scenario.controller_plant, scenario.constraint_space
    with pytest.raises(ValueError, match="mapping must be one of"):
        JointServoHybridController(plant, "tip", np.zeros(3), space, mapping="transpose")
    with pytest.raises(DimensionError, match="joint_gains must have 1 or 3 entries"):
        JointServoHybridController(plant, "tip", np.zeros(3), space, joint_gains=[1.0, 2.0])
    with pytest.raises(DimensionError, match="stiffness must have 1 or 2 entries"):
        AxisPDOpenLoopForceController(plant, "tip", np.zeros(3), space, stiffness=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="unknown baseline"):
        make_baseline("pid", plant, "tip", np.zeros(3), space)


def test_velocity_row_inertia_is_checked():
    scenario = build_scenario(CRANK.default_config(), with_loggers=False)
    with pytest.raises(DimensionError, match="velocity_row_inertia must be a 2x2 matrix of finite numbers"):
        type(scenario.controller)(scenario.controller_plant, scenario.robot.end_effector_frame,
                                  scenario.robot.end_effector_point, scenario.constraint_space,
                                  velocity_row_inertia=np.eye(3))


def test_crank_velocity_row_inertia_read_from_the_plant_is_the_handle_and_the_crank():
    """The spin row's inertia is the handle's spin moment; the crank-rate row's is the crank's joint
    inertia about its axis (arm and handle): both straight from the plant's models."""
    config = CRANK.default_config()
    config.mechanism.source = "plant"
    scenario = build_scenario(config, with_loggers=False)
    plant = scenario.plant
    I_v = scenario.task.velocity_row_inertia(plant, config, scenario.constraint_space)
    handle = plant.GetBodyByName("handle")
    assert I_v[0, 0] == pytest.approx(handle.default_rotational_inertia().get_moments()[2], rel=1e-9)
    context = plant.CreateDefaultContext()
    crank = plant.GetModelInstanceByName("crank")
    columns = plant.GetVelocitiesFromArray(crank, np.arange(plant.num_velocities())).astype(int)
    assert I_v[1, 1] == pytest.approx(plant.CalcMassMatrix(context)[columns[0], columns[0]], rel=1e-9)
    assert abs(I_v[0, 1]) < 1e-12


@pytest.mark.parametrize("mode", ["velocity-force", "position-force", "impedance-force"])
def test_crank_holds_its_design_in_every_mode_with_the_mechanism_and_tool_modelled(mode):
    """Linearized (sampled loop), every designed eigenvalue within 5 % once the mechanism's inertia
    along the velocity rows and the tool's inertial wrench are modelled (the paper's plain form, the
    default, misses by 5.1, 7.2 and 25.6 %: test_six_dof predicts those misses)."""
    config = CRANK.default_config().replace(mode=mode)
    config.mechanism.source = "plant"
    config.sensor.compensate_tool_inertia = True
    modelled = linearize_discrete(config, settle_time=0.5)
    assert modelled.equilibrium_residual < 1e-4
    assert modelled.match.relative_error.max() < 0.05, modelled.match.relative_error
    assert not np.any(modelled.match.unstable_extra)


def test_tool_inertia_compensation_alone_fixes_the_impedance_mode():
    """In impedance mode the 25.6 % miss is the tool's own inertia that the sensor reports and the law
    feeds forward (1 + I_h + I_t - M_p I_t): compensating it in the sensor is enough (the handle's
    I_h is 1e-5 kg m^2, a unit-mass impedance hardly notices it)."""
    config = CRANK.default_config().replace(mode="impedance-force")
    config.sensor.compensate_tool_inertia = True
    assert linearize_discrete(config, settle_time=0.5).match.relative_error.max() < 0.05


@pytest.mark.slow
def test_window_comparison_table_regenerates(monkeypatch):
    monkeypatch.syspath_prepend(str(DOCS))           # the script's own helpers (docs/report_format.py)
    spec = importlib.util.spec_from_file_location("make_baselines", DOCS / "make_baselines.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    rows = module.window_table(duration=1.5)
    assert [row["controller"] for row in rows] == [law[1] for law in module.WINDOW_LAWS]
    for row in rows:
        assert row["worst_real"] < 1e-6, row              # all stable on the window
    li_sastry = rows[0]
    assert li_sastry["velocity_error_percent"] < 1.0 and li_sastry["force_error_percent"] < 1.0


@pytest.mark.parametrize("compensate", [False, True])
def test_wrist_sensor_reports_no_wrench_off_contact_only_with_the_tool_inertia_compensated(compensate):
    """The window's arm swinging in free space (no contact) with arbitrary torques: the sensor's wrench is
    the tool's inertial wrench unless compensated, then zero (to the SAP solve's accuracy)."""
    config = get_task("window-washing").default_config()
    config.sensor = WristSensorConfig(compensate_tool_inertia=compensate)
    config.compensate_tangential_force = compensate      # allowed only with the tool's inertia removed
    scenario = build_scenario(config, with_loggers=False, sampled_plant_outputs=False)
    context = scenario.diagram.CreateDefaultContext()
    plant_context = scenario.plant_context(context)
    scenario.plant.SetPositions(plant_context, scenario.robot.arm, [-0.6, 0.4, 0.3])      # well below the pane
    scenario.plant.SetVelocities(plant_context, scenario.robot.arm, [1.0, -2.0, 3.0])
    controller_context = scenario.controller.GetMyMutableContextFromRoot(context)
    state = controller_context.get_discrete_state(0).CopyToVector()
    state[-3:] = [40.0, -20.0, 5.0]                                                        # held actuation
    controller_context.SetDiscreteState(0, state)
    wrench = scenario.sensor.GetOutputPort("wrench").Eval(scenario.sensor.GetMyContextFromRoot(context))
    if compensate:
        assert np.abs(wrench).max() < 1e-9, wrench
    else:
        assert np.abs(wrench[3:]).max() > 5.0             # m_t a of the 0.2 kg tool: 11 N here
