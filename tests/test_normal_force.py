"""The normal row's force along the tool's axis (control.normal_force, HybridController(normal_force_axis=...),
ToolConfig.normal_force): the formula on random input against its definition, float against AutoDiffXd,
and the controller's force row on a tilted disc against the force along its axis and the model's normal."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.normal_force import force_along_tool_axis, model_normal, normal_row
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import ArgumentError, ConfigError
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.tools import ToolConfig
from drake_hybrid.tasks.pressing import held_force_integral
from drake_hybrid.tasks.task_file import load_task_file

MODELS = Path(__file__).resolve().parents[1] / "models" / "tasks"
finite = st.floats(-50.0, 50.0, allow_nan=False)
vectors = st.lists(finite, min_size=3, max_size=3).map(np.array).filter(lambda v: np.linalg.norm(v) > 1e-3)


def _unit(v):
    return v / np.linalg.norm(v)


@settings(max_examples=200, deadline=None)
@given(moment=st.lists(finite, min_size=3, max_size=3), force=st.lists(finite, min_size=3, max_size=3),
       normal=vectors, axis=vectors)
def test_the_normal_component_becomes_the_component_along_the_axis_and_nothing_else_changes(moment, force, normal,
                                                                                          axis):
    n, a = _unit(normal), _unit(axis)
    wrench = np.concatenate([moment, force])
    read = force_along_tool_axis(wrench, n, a, lambda W: n @ W[3:])     # E_p's rows orthogonal to n
    signed = a if a @ n >= 0 else -a                  # the axis turned towards the model's normal
    assert read[:3] == pytest.approx(moment, abs=1e-12)                     # the moments as measured
    assert read[3:] @ n == pytest.approx(signed @ np.asarray(force), abs=1e-9)   # the normal row: along the axis
    tangential = np.asarray(force) - (np.asarray(force) @ n) * n                 # along the model's tangents
    assert read[3:] - (read[3:] @ n) * n == pytest.approx(tangential, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(wrench=st.lists(finite, min_size=6, max_size=6).map(np.array), covector=st.lists(finite, min_size=6,
       max_size=6).map(np.array), normal=vectors, axis=vectors)
def test_the_rows_reading_in_any_dual_basis_becomes_the_force_along_the_axis(wrench, covector, normal, axis):
    """A row that reads a wrench W as d . W (its dual vector d; E's dual basis): after the change, d . W' is the
    force along the axis, whatever d (but one that does not see the normal), and W' - W lies along the normal."""
    n, a = _unit(normal), _unit(axis)
    assume(abs(covector @ np.concatenate([np.zeros(3), n])) > 1e-2)
    read = force_along_tool_axis(wrench, n, a, lambda W: covector @ W)
    signed = a if a @ n >= 0 else -a
    assert covector @ read == pytest.approx(signed @ wrench[3:], rel=1e-9, abs=1e-7)
    change = read - wrench
    assert change[:3] == pytest.approx(np.zeros(3), abs=1e-12)
    assert np.linalg.norm(np.cross(change[3:], n)) <= 1e-9 * (1 + np.linalg.norm(change))


def test_a_row_that_does_not_see_the_normal_is_refused():
    blind = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])          # reads f_x; the normal is z
    with pytest.raises(ValueError, match="does not read the force along the model's normal"):
        force_along_tool_axis(np.ones(6), np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]),
                              lambda W: blind @ W)


@settings(max_examples=30, deadline=None)
@given(force=vectors, normal=vectors, axis=vectors)
def test_autodiff_values_are_the_floats_and_its_derivatives_the_finite_differences(force, normal, axis):
    n, a = _unit(normal), _unit(axis)
    assume_not_perpendicular = abs(a @ n) > 1e-3           # the sign flips there: the map is not smooth
    if not assume_not_perpendicular:
        return
    wrench = np.concatenate([np.zeros(3), force])
    a_ad = InitializeAutoDiff(a).ravel()
    along_normal = lambda W: n @ W[3:]                   # noqa: E731
    read = force_along_tool_axis(wrench.astype(object) + AutoDiffXd(0.0), n, a_ad, along_normal)
    assert ExtractValue(read).ravel() == pytest.approx(force_along_tool_axis(wrench, n, a, along_normal), abs=1e-12)
    step = 1e-6
    columns = [(force_along_tool_axis(wrench, n, a + step * e, along_normal)
                - force_along_tool_axis(wrench, n, a - step * e, along_normal))
               / (2 * step) for e in np.eye(3)]
    assert ExtractGradient(read) == pytest.approx(np.array(columns).T, abs=1e-6)


def test_the_model_normal_of_a_plane_row_is_the_planes_normal():
    task, config = load_task_file(MODELS / "disc_plane.yaml", register=False)
    space = task.constraint_space(config)
    model, _ = task.workpiece_surface(config)
    chart = PoseChart()
    x = chart.configuration(np.diag([1.0, -1.0, -1.0]), np.array([0.45, 0.0, 0.1]))
    row = normal_row(space.force_size, space.constraint.kinematic_rows)
    normal = model_normal(chart, space.constraint.force_projection(x), x, row)
    assert row == 0 and abs(normal @ model.unit_normal) == pytest.approx(1.0, abs=1e-12)


def test_the_tool_config_resolves_and_checks_the_normal_force():
    assert ToolConfig().normal_force_axis == "model"
    assert ToolConfig(kind="disc").normal_force_axis == "tool"
    assert ToolConfig(kind="disc", orientation="held").normal_force_axis == "model"
    assert ToolConfig(kind="disc", normal_force="model").normal_force_axis == "model"
    with pytest.raises(ConfigError, match=r"^tool.normal_force must be model or tool") as raised:
        ToolConfig(normal_force="sideways").validate()
    assert "\n" not in str(raised.value)


@pytest.fixture(scope="module")
def tilted_disc():
    """The disc-plane job's controller (its normal row along the tool's axis, the disc's default), a copy along
    the model's normal, and a state with the disc turned 6 deg off the model's plane."""
    _, config = load_task_file(MODELS / "disc_plane.yaml")
    scenario = build_scenario(config, with_loggers=False)
    root = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, root)
    state = scenario.plant.get_state_output_port(scenario.robot.arm).Eval(
        scenario.plant.GetMyContextFromRoot(root)).copy()
    state[4] += math.radians(6.0)                                   # the second wrist joint: the disc tilts
    tool = scenario.controller
    model = HybridController(**{**tool._arguments, "normal_force_axis": "model"})
    return config, tool, model, state


def _force_row(controller, state, wrench):
    context = controller.CreateDefaultContext()
    controller.GetInputPort("estimated_state").FixValue(context, state)
    controller.GetInputPort("measured_wrench").FixValue(context, wrench)
    for name, size in (("desired_velocity", controller.velocity_size), ("desired_acceleration",
                                                                          controller.velocity_size),
                       ("desired_force", controller.force_size)):
        controller.GetInputPort(name).FixValue(context, np.zeros(size))
    for name in ("contact_phase", "approach_reference", "path_position_error"):
        if controller.HasInputPort(name):
            port = controller.GetInputPort(name)
            port.FixValue(context, [2.0] if name == "contact_phase" else np.zeros(port.size()))
    plant = controller.kinematics.plant
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, state)
    kinematics = controller.kinematics.evaluate(plant_context, check=False)
    return controller.GetOutputPort("force").Eval(context), kinematics


def test_the_normal_row_reads_the_force_along_the_tools_axis_or_along_the_models_normal(tilted_disc):
    config, tool, model, state = tilted_disc
    assert tool.normal_force_axis == "tool" and config.tool.normal_force_axis == "tool"
    _, kinematics = _force_row(tool, state, np.zeros(6))
    axis = kinematics.rotation[:, 2]                       # the approach vector, into the surface
    space = tool.constraint_space
    normal = model_normal(space.chart, space.constraint.force_projection(kinematics.configuration),
                          kinematics.configuration, 0)
    tilt = math.degrees(math.acos(min(1.0, abs(axis @ normal))))
    assert tilt > 3.0                                      # the disc is off the model's plane
    # 20 N pressing along the disc's axis (on the robot: against the approach vector).
    wrench = np.concatenate([np.zeros(3), -20.0 * axis])
    along_axis, _ = _force_row(tool, state, wrench)
    along_normal, _ = _force_row(model, state, wrench)
    assert abs(along_axis[0]) == pytest.approx(20.0, rel=1e-9)
    assert abs(along_normal[0]) == pytest.approx(20.0 * abs(axis @ normal), rel=1e-9)
    assert along_axis[1:] == pytest.approx(along_normal[1:], abs=1e-12)       # the moment rows as measured


def test_a_bad_normal_force_axis_is_refused_naming_it(tilted_disc):
    _, tool, _, _ = tilted_disc
    with pytest.raises(ArgumentError, match=r"normal_force_axis must be one of model, tool, got 'wrist'"):
        HybridController(**{**tool._arguments, "normal_force_axis": "wrist"})


def test_a_disc_held_by_position_keeps_the_models_normal():
    _, config = load_task_file(MODELS / "disc_plane.yaml", register=False)
    config.tool = dataclasses.replace(config.tool, orientation="held")
    assert config.tool.normal_force_axis == "model"


def test_the_autodiff_controller_reads_the_same_normal_force(tilted_disc):
    """Both scalar types: the AutoDiffXd copy of the controller (its generic law) reads the force along the tool's
    axis as the float one (its compiled law) does."""
    _, tool, _, state = tilted_disc
    _, kinematics = _force_row(tool, state, np.zeros(6))
    wrench = np.concatenate([[0.1, -0.2, 0.05], -20.0 * kinematics.rotation[:, 2] + [0.5, -0.3, 0.0]])
    along_axis, _ = _force_row(tool, state, wrench)
    autodiff = tool.ToAutoDiffXd()
    context = autodiff.CreateDefaultContext()
    autodiff.GetInputPort("estimated_state").FixValue(context, InitializeAutoDiff(state).ravel())
    autodiff.GetInputPort("measured_wrench").FixValue(context, wrench.astype(object) + AutoDiffXd(0.0))
    for index in range(autodiff.num_input_ports()):
        port = autodiff.get_input_port(index)
        if not port.HasValue(context):
            value = [2.0] if port.get_name() == "contact_phase" else np.zeros(port.size())
            port.FixValue(context, np.asarray(value, dtype=object) + AutoDiffXd(0.0))
    read = autodiff.GetOutputPort("force").Eval(context)
    assert ExtractValue(read).ravel() == pytest.approx(along_axis, rel=1e-9, abs=1e-9)


def test_a_start_read_along_the_models_normal_holds_the_desired_force_with_no_integral():
    scenario = type("Scenario", (), {"controller": type("Controller", (), {"normal_force_axis": "model"})()})()
    held, xi = held_force_integral(scenario, np.zeros(6), [20.0, 0.0, 0.0])
    assert held.tolist() == [20.0, 0.0, 0.0] and xi.tolist() == [0.0, 0.0, 0.0]
