"""The window-washing task end to end: 1 kHz simulation, linearization, CLI files, sensors."""

import json

import numpy as np
import pytest
from run_checks import assert_rows_settled_within

from pydrake.geometry import Role
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.analysis.design import design_time_constant, predicted_eigenvalues
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.cli import main
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.systems.contact_wrench_sensor import ContactWrenchSensor
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor
from drake_hybrid.tasks.config import dump_config, load_config
from drake_hybrid.tasks.plant import build_plant
from drake_hybrid.tasks.registry import get_task

TASK = get_task("window-washing")


@pytest.fixture(scope="module")
def default_run():
    return simulate(TASK.default_config())


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_velocity_and_force_errors_settle_below_one_percent_within_five_time_constants(default_run):
    log, summary = default_run.log, default_run.summary
    tau = summary.design_time_constant
    settled = log["t"] >= 5 * tau
    speed = np.linalg.norm(log["desired_velocity"], axis=1)
    force = np.linalg.norm(log["desired_force"], axis=1)
    velocity_error = np.linalg.norm(log["velocity_error"], axis=1)
    force_error = np.linalg.norm(log["force_error"], axis=1)
    assert np.all(velocity_error[settled] < 0.01 * speed[settled])
    assert np.all(force_error[settled] < 0.01 * force[settled])
    assert summary.velocity_settling_time_1_percent <= 5 * tau
    assert summary.force_settling_time_1_percent <= 5 * tau
    # The start really had the designed transients to settle from.
    assert velocity_error[0] == pytest.approx(0.1)
    assert np.max(force_error) > 0.15 * force[0]
    # On the window throughout: the pad centre stays within its compression (about 1 mm) of y = 0.98.
    assert summary.max_constraint_residual < 2e-3
    assert np.all(np.abs(log["torque"]) <= np.array([150.0, 80.0, 30.0]))


def test_transients_follow_the_designed_exponentials(default_run):
    """Velocity error e^(-K_v t) e(0) and force error -G e^(-G t) xi(0), within 5 % of the initial error."""
    from drake_hybrid.experiments.simulation import predicted_tracking

    log = default_run.log
    predicted_velocity, predicted_force = predicted_tracking(default_run.scenario, default_run.config, log)
    early = log["t"] <= 0.5
    velocity_deviation = np.abs(log["velocity"] - predicted_velocity)[early].max()
    assert velocity_deviation < 0.05 * np.abs(log["velocity_error"][0]).max()
    after_contact_transient = (log["t"] >= 0.05) & early     # the compliant contact needs ~20 ms to build F
    force_deviation = np.abs(log["force"] - predicted_force)[after_contact_transient].max()
    initial_force_error = 10.0 * 0.2                          # G xi(0) = (15 / 1.5) * 0.2 N
    assert force_deviation < 0.05 * initial_force_error


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_position_mode_tracks(tmp_path):
    config = TASK.default_config()
    config.mode = "position-force"
    config.duration = 3.0          # slowest designed root -2 (s^2 + 10 s + 16): 5 time constants = 2.5 s
    result = simulate(config)
    log, summary = result.log, result.summary
    assert_rows_settled_within(summary, 1.0)
    assert np.abs(log["position_error"][-1]).max() < 1e-3          # the integrated position error is regulated


@pytest.mark.parametrize("mode", ["velocity-force", "position-force"])
def test_linearized_eigenvalues_match_the_design(mode):
    config = TASK.default_config()
    config.mode = mode
    result = linearize_continuous(config)
    match = result.match
    assert result.equilibrium_residual < 1e-6
    assert match.matched, match.as_dict()
    assert np.all(match.relative_error <= 0.05)
    assert np.all(match.extra.real < 0)
    designed = predicted_eigenvalues(config.gains.matrices(2, 1, mode), mode)
    np.testing.assert_allclose(np.sort_complex(match.predicted), np.sort_complex(designed.designed))
    # The k = 2 marginal modes (unregulated positions, or e_p moving with them) stay at 0 to 1e-2.
    assert len(match.marginal_partners) == 2
    assert np.all(np.abs(match.marginal_partners) < 1e-2)


def test_cli_simulate_and_analyze_write_the_documented_files(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", "window-washing", "--duration", "0.3", "--out", str(out), "--no-progress"]) == 0
    log = np.load(out / "log.npz")
    n = len(log["t"])
    assert n >= 300
    assert log["velocity"].shape == log["desired_velocity"].shape == (n, 2)
    assert log["force"].shape == log["desired_force"].shape == log["constraint"].shape == (n, 1)
    assert log["torque"].shape == (n, 3)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mode"] == "velocity-force"
    assert set(summary["gains"]) == {"velocity", "position", "force_proportional", "force_integral", "force_damping",
                                     "impedance_mass"}
    assert summary["gains"]["velocity"] == [[10.0, 0.0], [0.0, 8.0]]
    assert summary["predicted_eigenvalues"] == [[-10.0, 0.0], [-8.0, 0.0], [-10.0, 0.0]]
    assert (out / "velocity_tracking.png").stat().st_size > 10_000
    assert (out / "force_tracking.png").stat().st_size > 10_000
    printed = capsys.readouterr().out
    assert "velocity x-dot: command 0.1 m/s; final error" in printed and "velocity theta-dot: command 0;" in printed
    eigen = tmp_path / "eig.json"
    assert main(["analyze", "window-washing", "--mode", "position-force", "--json", str(eigen)]) == 0
    data = json.loads(eigen.read_text())
    assert data["matched"] is True
    assert data["mode"] == "position-force" and data["velocity_dim"] == 2 and data["force_dim"] == 1
    assert {"predicted", "closed_loop", "gains"} <= set(data)
    assert all(len(pair) == 2 for pair in data["predicted"] + data["closed_loop"])


def test_config_round_trips_through_yaml():
    config = TASK.default_config()
    text = dump_config(config)
    loaded = load_config(data=text)
    assert dump_config(loaded) == text          # (Drake's config structs compare by identity)
    changed = load_config(data="mode: position-force\ngains:\n  velocity: [3.0]\n", defaults=config)
    assert changed.mode == "position-force" and changed.gains.velocity == [3.0]
    assert changed.gains.force_integral == config.gains.force_integral


def test_relaxation_times_reach_the_pad_and_the_workpiece():
    """SAP adds the pad's and the workpiece's relaxation times (Drake's 0.1 s where one is unset):
    contact.relaxation_time sets the pad's, contact.workpiece_relaxation_time the workpiece's."""
    def relaxation_times(pad, workpiece):
        config = TASK.default_config()
        config.contact.relaxation_time, config.contact.workpiece_relaxation_time = pad, workpiece
        plant, scene_graph, robot = build_plant(TASK, config, DiagramBuilder())
        inspector = scene_graph.model_inspector()
        found = {}
        for geometry in inspector.GetAllGeometryIds(Role.kProximity):
            if plant.GetBodyFromFrameId(inspector.GetFrameId(geometry)).model_instance() == robot.arm:
                continue                      # the links' collision rods: for the start's clearance check only
            properties = inspector.GetProximityProperties(geometry)
            key = "pad" if geometry in robot.pad_geometries else "workpiece"
            found.setdefault(key, []).append(properties.GetPropertyOrDefault("material", "relaxation_time", None))
        return found

    assert relaxation_times(0.01, 0.0) == {"pad": [0.01], "workpiece": [0.0]}
    assert relaxation_times(-1.0, -1.0) == {"pad": [None], "workpiece": [None]}


def test_start_off_the_window_is_rejected():
    """A start that should press on the window but is 10 mm off it is rejected; the message says how to
    ask for an approach instead (start.in_contact: false, see tests/test_reliability.py)."""
    from drake_hybrid.scenario.start import check_start

    config = TASK.default_config()
    scenario = build_scenario(config, with_loggers=False)
    q_off = TASK.inverse_kinematics(config, 0.9, 0.97, np.pi / 2)
    with pytest.raises(ValueError, match=r"not on constraint 'window': C = \[-0.01\] exceeds tolerance.*"
                                         r"set start.in_contact: false"):
        check_start(scenario, q_off)


def sensor_readings_at_rest(task):
    """Both sensors on one discrete plant pressing at the task's start at rest: one forced step
    with the static torque, then (contact sensor, wrist sensor) readings."""
    from drake_hybrid.scenario.start import static_torque

    config = task.default_config()
    scenario = build_scenario(config, with_loggers=False)
    builder = DiagramBuilder()
    plant, _, robot = build_plant(task, config, builder)
    bodies = [plant.get_body(i) for m in robot.model_instances for i in plant.GetBodyIndices(m)]
    contact = builder.AddSystem(ContactWrenchSensor(plant, bodies, robot.end_effector_frame, robot.end_effector_point))
    wrist = builder.AddSystem(WristForceTorqueSensor(plant, robot.tool_weld, robot.end_effector_frame,
                                                     robot.end_effector_point))
    builder.Connect(plant.get_contact_results_output_port(), contact.get_input_port(0))
    builder.Connect(plant.get_reaction_forces_output_port(), wrist.get_input_port(0))
    for sensor in (contact, wrist):
        builder.Connect(plant.get_body_poses_output_port(), sensor.get_input_port(1))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = task.start_positions(scenario)
    torque = static_torque(scenario, q)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       scenario.constraint_space.chart)
    arm_columns = plant.GetVelocitiesFromArray(robot.arm, np.arange(plant.num_velocities())).astype(int)
    for _ in range(5):
        # Static: the torque that balances gravity and the wrench of the last step, so the arm (and
        # with it the tool, whose inertia the wrist sensor would feel) does not accelerate.
        plant.SetPositions(plant_context, robot.arm, q)
        plant.SetVelocities(plant_context, robot.arm, np.zeros(len(q)))
        plant.get_actuation_input_port(robot.arm).FixValue(plant_context, torque)
        plant.ExecuteForcedEvents(plant_context, publish=False)
        plant.SetPositions(plant_context, robot.arm, q)
        plant.SetVelocities(plant_context, robot.arm, np.zeros(len(q)))
        wrench = contact.get_output_port(0).Eval(contact.GetMyContextFromRoot(context))
        J = kinematics.evaluate(plant_context).spatial_jacobian[:, arm_columns]
        torque = -plant.CalcGravityGeneralizedForces(plant_context)[arm_columns] - J.T @ wrench
    assert abs(wrist.tool_mass() * 9.81) > 1.0                               # the compensation matters
    return (contact.get_output_port(0).Eval(contact.GetMyContextFromRoot(context)),
            wrist.get_output_port(0).Eval(wrist.GetMyContextFromRoot(context)))


def test_wrist_sensor_agrees_with_contact_sensor_once_tool_weight_is_compensated():
    from_contact, from_wrist = sensor_readings_at_rest(TASK)
    assert from_contact[5] == pytest.approx(-10.0, rel=1e-3)                 # pressing up: -10 N on the robot
    np.testing.assert_allclose(from_wrist, from_contact, atol=1e-6 * 10.0)


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_simulation_with_the_wrist_sensor_and_filter():
    config = TASK.default_config()
    # The tool's inertia removed: the law cancels the measured F_v (compensate_tangential_force),
    # which must be the contact's alone (scenario.config refuses the two together otherwise).
    config.sensor = WristSensorConfig(bandwidth_hz=100.0, compensate_tool_inertia=True)
    config.duration = 1.5
    summary = simulate(config).summary
    assert_rows_settled_within(summary, 1.0)


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_redundant_four_joint_arm_tracks_and_damps_its_null_space():
    config = TASK.default_config()
    config.task_parameters["joints"] = 4
    config.duration = 1.5
    result = simulate(config)
    summary = result.summary
    assert_rows_settled_within(summary, 1.0)
    assert design_time_constant(result.scenario.controller.validated_gains(), "velocity-force") == pytest.approx(0.125)


def test_loggers_read_the_tick_and_do_not_rerun_the_law(monkeypatch):
    """With a sampled controller the scenario logs the diagnostics stored at each tick
    (``sampled_diagnostics``): the same numbers as logging the live ports, one law per tick."""
    from pydrake.systems.analysis import Simulator

    import drake_hybrid.station.loop as scenarios

    config = get_task("window-washing").default_config()
    config.duration = 0.1
    original = scenarios.HybridController
    logs, evaluations = {}, {}
    for sampled in (True, False):
        if not sampled:      # the same diagram with the live output ports logged instead
            monkeypatch.setattr(scenarios, "HybridController",
                                lambda *a, **kw: original(*a, **{**kw, "sampled_diagnostics": False}))
        # Sampled plant outputs: the wrench then stays what the tick read until the next plant step,
        # so the live re-evaluation can equal the tick (unsampled, it is recomputed with the new
        # actuation: the very re-evaluation that the sampled diagnostics avoid).
        scenario = build_scenario(config, sampled_plant_outputs=True)
        assert scenario.controller.sampled_diagnostics is sampled
        count = [0]
        law = scenario.controller._evaluate_law

        def counted(*args, law=law, count=count):
            count[0] += 1
            return law(*args)

        scenario.controller._evaluate_law = counted
        simulator = Simulator(scenario.diagram)
        context = simulator.get_mutable_context()
        set_initial_conditions(scenario, context)
        simulator.Initialize()
        count[0] = 0
        simulator.AdvanceTo(config.duration)
        evaluations[sampled] = count[0]
        logs[sampled] = {name: (logger[0] if isinstance(logger, tuple) else logger).FindLog(context).data()
                         for name, logger in scenario.loggers.items()}
    ticks = round(config.duration / config.control_period)
    assert evaluations[True] == pytest.approx(ticks, abs=1)
    assert evaluations[False] == pytest.approx(2 * ticks, abs=2)
    for name, columns in scenario.controller.diagnostic_slices().items():
        np.testing.assert_array_equal(logs[True][name][columns], logs[False][name])
