"""Bad paths, gains and starts refused before the run, each with a one-line typed error naming the field
(and the file, for a task file) and what to do; and what a user's own station gets right without help:
the force per waypoint or by arc length, a height map's edge, a tool on a frame no joint moves, waypoints
beside a task's pattern, a height map's frame, a pattern beyond the surface, a task file's start off its
constraint, a start without the collision filters, the path's loggers, a row's rounding-sized command,
a planar arm through the pane, a gain array of three dimensions."""

import airo_models
import numpy as np
import pytest

from pydrake.geometry import Box
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import (ArgumentError, ConfigError, GainError, OffConstraintError, PathError,
                                      StartCollisionError)
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, view_projection
from drake_hybrid.experiments.metrics import row_errors, row_scales
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.arm import mount_tool, robot_plant
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config
from drake_hybrid.station.contact_start import solve_path_start
from drake_hybrid.station.loggers import PATH_LOGS, add_loggers
from drake_hybrid.station.loop import add_hybrid_controller
from drake_hybrid.station.parsing import models_directory
from drake_hybrid.station.path_config import ForcePointConfig, PathConfig, PatternConfig, WaypointConfig
from drake_hybrid.station.path_job import path_job
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.tasks.path import build_path, with_path
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task_file import load_task_file

TASKS = models_directory() / "tasks"
UR5E_GUESS = [0.0, -1.9, 1.9, -1.6, -1.57, 0.0]


def small_bump(name="bump"):
    """A 9 x 9 height map, 1 cm apart, a 1 cm bump in the middle, at (0.45, 0, 0.1)."""
    x = y = np.linspace(-0.04, 0.04, 9)
    X, Y = np.meshgrid(x, y)
    return HeightMapSurface(HeightMap(x, y, 0.01 * np.exp(-(X ** 2 + Y ** 2) / 0.03 ** 2), name=name),
                            RigidTransform([0.45, 0.0, 0.1]))


# -- the path's fields -------------------------------------------------------------------------------

def test_a_force_per_waypoint_and_by_arc_length_together_are_refused():
    """Both give the path's force: the waypoints' were dropped without a word; now both fields are named."""
    plane = PlaneSurface([0.45, 0.0, 0.1], [0.0, 0.0, 1.0])
    settings = PathConfig(waypoints=[WaypointConfig([0.45, 0.0, 0.1], 12.0), WaypointConfig([0.48, 0.0, 0.1], 15.0)],
                          force_by_arc_length=[ForcePointConfig(0.0, 5.0), ForcePointConfig(0.03, 5.0)])
    with pytest.raises(PathError, match=r"^path\.waypoints\[\]\.force and path\.force_by_arc_length both give the "
                                        r"path's force .*: give one of them$"):
        path_job(plane, 0.02, settings)
    # Either alone is the path's force.
    waypoints_only = PathConfig(waypoints=settings.waypoints)
    assert path_job(plane, 0.02, waypoints_only).path.force(0.0) == pytest.approx(12.0)


def test_waypoints_past_a_height_maps_edge_are_refused():
    """Past the grid the surface is the spline's extrapolation, not the part: the waypoint is named."""
    bump = small_bump()
    inside = [0.45, 0.0, float(bump.closest_point([0.45, 0.0, 0.12])[0][2])]
    beyond = [0.45 + 0.06, 0.0, 0.1]                                     # 2 cm past the grid's edge
    settings = PathConfig(waypoints=[WaypointConfig(inside), WaypointConfig(beyond)], tolerance=0.01)
    with pytest.raises(PathError, match=r"path\.waypoints\[1\]\.point .* outside the grid's"):
        path_job(bump, 0.005, settings)


def test_a_path_whose_curve_leaves_the_map_between_waypoints_is_refused():
    """The waypoints on the grid but the path between them off it (less the pad's radius): named by arc length."""
    bump = small_bump()
    corners = [(-0.02, -0.02), (0.024, -0.02), (0.024, 0.02), (-0.02, 0.02)]    # within the grid less 15 mm
    points = [[0.45 + x, y, float(bump.closest_point([0.45 + x, y, 0.12])[0][2])] for x, y in corners]
    with pytest.raises(PathError, match=r"path\.waypoints: the path at arc length 0\.01.* m \(keep the path on the map, "
                                        r"the pad's radius inside its edge\) is at map \(x, y\) = .* outside the grid"):
        path_job(bump, 0.015, PathConfig(waypoints=[WaypointConfig(p) for p in points], tolerance=0.01))
    # Straight between the same waypoints, the path stays on the map.
    path_job(bump, 0.015, PathConfig(waypoints=[WaypointConfig(p) for p in points], tolerance=0.01,
                                     interpolation="linear"))


def test_waypoints_on_a_task_whose_default_path_is_a_pattern_name_both_and_how_to_clear_it():
    task = get_task("surface-polishing")
    config = with_path(task.default_config(), waypoints=[WaypointConfig([0.45, 0.0, 0.25]),
                                                         WaypointConfig([0.47, 0.0, 0.248])])
    with pytest.raises(PathError, match=r"^path\.waypoints and pattern \(kind 'raster'\): give waypoints or a pattern, "
                                        r"not both; .*the task's default path: clear it with path\.pattern\.kind: ''"):
        build_path(task, config)


def test_a_pattern_beyond_the_surface_as_the_view_sees_it_names_the_pattern():
    pipe = CylinderSurface(center=[0.45, 0.0, 0.1], axis=[0.0, 1.0, 0.0], radius=0.1, length=0.4)
    wide = PathConfig(pattern=PatternConfig(kind="raster", size=[0.1, 0.3], spacing=0.03))
    with pytest.raises(PathError, match=r"^path: stroke 0 at \(u, v\) = \(-0.05, -0.15\) m is off 'cylinder' as the view "
                                        r"sees it \(the view's line misses the surface\); keep the pattern on the "
                                        r"surface: make path\.pattern\.size smaller or move path\.pattern\.center$"):
        path_job(pipe, 0.02, wide)
    long = PathConfig(pattern=PatternConfig(kind="raster", size=[0.6, 0.1], spacing=0.03))
    with pytest.raises(PathError, match=r"beyond the cylinder's length \(0\.4 m\)\); keep the pattern on the surface"):
        path_job(pipe, 0.02, long)


# -- task files ----------------------------------------------------------------------------------------

def test_a_non_finite_height_map_frame_names_the_field_and_the_file(tmp_path):
    text = (TASKS / "raster_bump.yaml").read_text().replace("X_WM: {translation: [0.45, 0.0, 0.15]}",
                                                            "X_WM: {translation: [0.45, .nan, 0.15]}")
    (tmp_path / "bump_part.csv").write_text((TASKS / "bump_part.csv").read_text())
    path = tmp_path / "nan_frame.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"^.*nan_frame\.yaml: workpiece\.surface\.X_WM must be a transform of finite "
                                          r"numbers"):
        load_task_file(path, register=False)
    with pytest.raises(PathError, match="HeightMapSurface: X_WM must be a RigidTransform of finite numbers"):
        HeightMapSurface(small_bump().height_map, RigidTransform([0.0, np.nan, 0.0]))


def window_file(tmp_path, name, **replacements):
    text = (TASKS / "window_washing.yaml").read_text().replace("name: window-washing-file", f"name: {name}")
    for old, new in replacements.items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    return load_task_file(path)


def test_a_task_files_start_off_its_constraint_names_the_file_and_the_field(tmp_path):
    task, config = window_file(tmp_path, "window-start-off", **{
        'configuration: ["0.9", "window_height - pad_radius", "pi/2"]':
            'configuration: ["0.9", "window_height - pad_radius - 0.01", "pi/2"]'})
    scenario = build_scenario(config.replace(duration=0.1), with_loggers=False)
    with pytest.raises(OffConstraintError, match=r"window-start-off\.yaml: start\.configuration is off the constraint, "
                                                 r"\|C\| = 0\.01 > start\.tolerance .*give a start\.configuration with"):
        set_initial_conditions(scenario, scenario.diagram.CreateDefaultContext())
    # A file that gives its start as start.pose is named by that field.
    plate, _ = load_task_file(TASKS / "ur10_plate.yaml", register=False)
    assert plate.start_field() == (str(TASKS / "ur10_plate.yaml"), "start.pose")


def test_a_planar_arm_through_the_pane_at_its_start_is_refused(tmp_path):
    """The planar arms' links are collision rods now (only the pad touches in the run), so the start's clearance
    check sees the elbow-up solution through a pane lowered to 0.5 m."""
    task, config = window_file(tmp_path, "window-elbow-up", **{
        "window_height: 1.0": "window_height: 0.5",
        "X_PC: {translation: [1.0, 0.0, 1.0]}": "X_PC: {translation: [1.0, 0.0, 0.5]}",
        "joint_guess: [-0.115, 1.803, -0.117]": "joint_guess: [1.054, -2.093, 2.61]"})
    scenario = build_scenario(config.replace(duration=0.1), with_loggers=False)
    with pytest.raises(StartCollisionError, match=r"body 'link[12]' \(planar_3r::rod\) .* mm into window::glass"):
        set_initial_conditions(scenario, scenario.diagram.CreateDefaultContext())
    # The elbow below the pane (the file's own guess) starts.
    task, config = window_file(tmp_path, "window-elbow-down", **{
        "window_height: 1.0": "window_height: 0.5",
        "X_PC: {translation: [1.0, 0.0, 1.0]}": "X_PC: {translation: [1.0, 0.0, 0.5]}",
        "joint_guess: [-0.115, 1.803, -0.117]": "joint_guess: [-0.658, 2.093, 0.136]"})
    scenario = build_scenario(config.replace(duration=0.1), with_loggers=False)
    set_initial_conditions(scenario, scenario.diagram.CreateDefaultContext())


# -- a user's own station --------------------------------------------------------------------------------

def add_ur5e(plant, frame="tool0", weld_first=True):
    arm = Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]
    if weld_first:
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
    robot = mount_tool(plant, arm, frame)
    if not weld_first:
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
    return robot


def plate_space(chart=None):
    chart = chart or PoseChart()
    plate = PlaneSurface([0.45, 0.0, 0.1], [0.0, 0.0, 1.0])
    return plate, ConstraintSpace(plate.offset_constraint(chart, 0.02), view_projection(chart, plate.default_view()))


def test_a_tool_on_a_frame_no_joint_moves_is_refused_by_every_block():
    """The arm's base: refused by mount_tool (welded first), robot_plant and add_hybrid_controller (welded after
    the tool), not later by the inverse kinematics."""
    with pytest.raises(ArgumentError, match=r"^mount_tool: flange_frame 'base_link' \(on body 'base_link'\) is welded "
                                            r"to the world: no joint moves it"):
        add_ur5e(MultibodyPlant(0.0), "base_link")
    with pytest.raises(ArgumentError, match=r"^robot_plant: no joint of the arm 'ur5e' moves the end-effector frame "
                                            r"'pad_center'"):
        robot_plant(lambda plant: add_ur5e(plant, "base_link", weld_first=False))
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(default_plant_config(), builder)
    robot = add_ur5e(plant, "base_link", weld_first=False)
    plant.Finalize()
    with pytest.raises(ArgumentError, match=r"^add_hybrid_controller: no joint of the arm 'ur5e' moves the end-effector "
                                            r"frame 'pad_center' .*mount_tool it on the frame at the end of the arm"):
        add_hybrid_controller(builder, plant, robot, plate_space()[1], robot_plant(add_ur5e))


@pytest.fixture(scope="module")
def unfiltered_job():
    """A raster on a plate in a user's diagram, the collision filters (only_tool_touches) forgotten, the loggers
    added with period=None."""
    plate, space = plate_space()
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    robot = add_ur5e(plant)
    workpiece = add_rigid_workpiece(plant, Box(0.3, 0.3, 0.02), RigidTransform([0.45, 0.0, 0.09]))
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    job = path_job(plate, 0.02, PathConfig(pattern=PatternConfig(kind="raster", size=[0.03, 0.015], spacing=0.015),
                                           force=8.0))
    hybrid = add_hybrid_controller(
        builder, plant, robot, space, robot_plant(add_ur5e), mode="position-force", control_period=1e-3,
        gains=HybridGains(velocity=[30.0] * 3, position=[200.0] * 3, force_proportional=[0.5, 0.0, 0.0],
                          force_integral=[15.0, 1.0, 1.0]),
        path=job, supervision=SupervisionConfig(), initial_phase=ContactPhase.APPROACH)
    loggers = add_loggers(builder, hybrid, period=None)
    return builder.Build(), hybrid, loggers


def test_a_start_without_the_collision_filters_names_only_tool_touches(unfiltered_job):
    diagram, hybrid, _ = unfiltered_job
    with pytest.raises(ConfigError, match=r"^prime_start: .*without hydroelastic representation.* -- .*let only the "
                                          r"tool touch it \(only_tool_touches after plant\.Finalize\(\)\)$"):
        solve_path_start(diagram, diagram.CreateDefaultContext(), hybrid, UR5E_GUESS)


def test_a_path_jobs_loggers_take_period_none(unfiltered_job):
    _, hybrid, loggers = unfiltered_job
    assert set(PATH_LOGS) | {"lifting", "wrench"} <= set(loggers)


# -- figures and gains ----------------------------------------------------------------------------------

def test_a_rounding_sized_command_is_no_scale_for_its_rows_percent():
    """A path's spin row commanded about 1e-7 rad/s beside 0.05 m/s: its error is judged against the run's scale,
    not against the rounding."""
    t = np.linspace(0.0, 1.0, 101)
    desired = np.column_stack([np.full(101, 1e-7), np.full(101, 0.05), np.zeros(101)])
    error = np.column_stack([np.full(101, 6e-5), np.full(101, 1e-4), np.full(101, 1e-4)])
    scales, sources = row_scales(desired, ["rad/s", "m/s", "m/s"])
    assert sources == ["run", "command", "rows in its units"]
    assert scales[0] == pytest.approx(np.hypot(1e-7, 0.05))
    rows = row_errors(t, error, desired, ["spin", "x", "y"], ["rad/s", "m/s", "m/s"], 0.0, 0.5)
    assert rows[0].max_error_percent_after_5_time_constants == pytest.approx(100 * 6e-5 / np.hypot(1e-7, 0.05))
    # A meridian's spin row, commanded 3.1e-5 rad/s by the path's splines (measured on the sphere), is noise too;
    # a command above the floor is the row's own scale, as before.
    desired[:, 0] = 3.1e-5
    assert row_scales(desired, ["rad/s", "m/s", "m/s"])[1][0] == "run"
    desired[:, 0] = 0.01
    assert row_scales(desired, ["rad/s", "m/s", "m/s"])[1][0] == "command"


@pytest.mark.parametrize("gain", [np.ones((2, 2, 1)), 10 * np.eye(2).reshape(2, 2, 1)])
def test_a_gain_of_three_dimensions_is_refused_by_its_shape(gain):
    with pytest.raises(GainError, match=r"^HybridGains: velocity must be a scalar, a vector \(the diagonal\) or a k x k "
                                        r"matrix, got an array of shape \[2, 2, 1\]$"):
        HybridGains(velocity=gain)

