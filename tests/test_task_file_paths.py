"""The task file's parts for jobs over a surface (tasks/task_file_surface.py): a height-map workpiece by
file, the path section, the paper's fields Y_d(r), F_d(r) as expressions; each bad section a one-line
error naming the field."""

import textwrap

import numpy as np
import pytest

from drake_hybrid.core.errors import ConfigError, PathError
from drake_hybrid.core.height_field import HeightFieldConstraint
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.station.parsing import models_directory
from drake_hybrid.systems.path_source import PathSource
from drake_hybrid.systems.sources import DesiredFieldSource
from drake_hybrid.tasks.path import build_path
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task_file import load_task_file

TASKS = models_directory() / "tasks"
WINDOW = (TASKS / "window_washing.yaml").read_text()


def write(tmp_path, text, name="task.yaml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_the_height_map_file_gives_the_constraint_the_view_rows_the_geometry_and_the_start():
    task, config = load_task_file(TASKS / "raster_bump.yaml")
    space = task.constraint_space(config)
    assert isinstance(space.constraint, HeightFieldConstraint) and space.constraint.kinematic_rows == (1, 2)
    x = np.asarray(config.start.configuration)
    np.testing.assert_allclose(space.constraint.value(x), 0.0, atol=1e-8)      # the path's first point, on C = 0
    rows = space.velocity_projection.matrix(x)
    np.testing.assert_allclose(rows[1:], [[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0]])   # x . c-dot, y . c-dot
    np.testing.assert_allclose(rows[0, 3:], x[3:].reshape(3, 3)[:, 2])              # the spin about a
    surface, offset = task.workpiece_surface(config)
    assert offset == 0.02 and surface.height_map.heights.shape == (41, 41)
    scenario = build_scenario(config.replace(duration=0.1), with_loggers=False)
    assert isinstance(scenario.source, PathSource)
    assert scenario.controller.get_path_position_error_input_port() is not None
    assert scenario.supervisor.lift_off
    inspector = scenario.scene_graph.model_inspector()
    names = [inspector.GetName(g) for g in inspector.GetAllGeometryIds()]
    assert "surface" in names                                                       # the part's mesh


def window_with(extra, config_extra=""):
    """The window-washing file with more sections (and more config)."""
    return WINDOW.replace("name: window-washing-file", "name: window-file-variant") + extra + config_extra


def test_the_papers_fields_are_expressions_run_by_the_field_source(tmp_path):
    """Y_d(r) = (0.1 (1 - x), 0, 0) and F_d(r) = -(10 + 5 x) in the window's chart: the source outputs
    E_p Y_d and F_d at the measured configuration, and the start presses with F_d(r_0)."""
    path = write(tmp_path, window_with('fields:\n  velocity: ["0.1 * (1 - x)", "0", "0"]\n  force: ["-(10 + 5 * x)"]\n'))
    task, config = load_task_file(path)
    assert config.desired_force.value == pytest.approx([-(10 + 5 * 0.9)])
    scenario = build_scenario(config.replace(duration=0.1), with_loggers=False)
    source = scenario.source
    assert isinstance(source, DesiredFieldSource)
    context = source.CreateDefaultContext()
    plant = scenario.controller_plant
    plant_context = plant.CreateDefaultContext()
    q = task.start_positions(scenario)
    plant.SetPositions(plant_context, q)
    source.get_input_port(0).FixValue(context, plant.GetPositionsAndVelocities(plant_context))
    x = scenario.controller.kinematics.evaluate(plant_context).configuration
    np.testing.assert_allclose(source.GetOutputPort("desired_velocity").Eval(context), [0.1 * (1 - x[0]), 0.0],
                               atol=1e-12)
    np.testing.assert_allclose(source.GetOutputPort("desired_force").Eval(context), [-(10 + 5 * x[0])], atol=1e-12)


@pytest.mark.parametrize("extra, message", [
    ('fields:\n  velocity: ["0.1", "0"]\n  force: ["-10"]\n', r"fields\.velocity must have d = 3 expressions, got 2"),
    ('fields:\n  velocity: ["0.1", "0", "0"]\n  force: ["-10", "0"]\n', r"fields\.force must have m = 1"),
    ('fields:\n  velocity: ["0.1", "0", "0"]\n', r"fields: give both velocity"),
    ('fields:\n  velocity: ["0.1 * q1", "0", "0"]\n  force: ["-10"]\n', r"fields\.velocity\[0\]"),
])
def test_bad_fields_are_one_line_errors_naming_the_field(tmp_path, extra, message):
    with pytest.raises(ConfigError, match=message) as error:
        load_task_file(write(tmp_path, window_with(extra)))
    assert "\n" not in str(error.value)


BUMP = (TASKS / "raster_bump.yaml").read_text()


@pytest.mark.parametrize("change, error, message", [
    (("kind: height_map", "kind: cone"), ConfigError, r"workpiece\.surface\.kind must be one of plane, sphere"),
    (("file: bump_part.csv", "file: missing.csv"), PathError, r"workpiece\.surface: height map file .* does not exist"),
    (("spacing: [0.004, 0.004]", "spacing: [0.0, 0.004]"), PathError, r"the spacing must be positive"),
    (("speed: 0.05", "speed: 0.0"), PathError, r"config\.path\.speed must be positive"),
    (("acceleration: 0.5", "acceleration: -1.0"), PathError, r"config\.path\.acceleration must be positive"),
    (("size: [0.1, 0.1]", "size: [0.2, 0.1]"), PathError, r"the pattern's corner is at map .* outside the grid"),
    (("spacing: 0.02, direction: u", "spacing: 0.02, direction: w"), PathError, r"pattern\.direction must be u or v"),
])
def test_a_bad_job_file_is_a_one_line_error_before_the_run(tmp_path, change, error, message):
    (tmp_path / "bump_part.csv").write_text((TASKS / "bump_part.csv").read_text())
    text = BUMP.replace(*change)
    assert text != BUMP
    with pytest.raises(error, match=message) as raised:
        task, config = load_task_file(write(tmp_path, text))
        build_scenario(config.replace(duration=0.1), with_loggers=False)
    assert "\n" not in str(raised.value)


def test_a_scan_with_a_hole_is_refused_when_the_file_is_loaded(tmp_path):
    heights = np.loadtxt(TASKS / "bump_part.csv", delimiter=",")
    heights[12, 30] = np.nan
    np.savetxt(tmp_path / "bump_part.csv", heights, delimiter=",")
    with pytest.raises(PathError, match=r"1 height\(s\) missing or not finite, the first at row 12, column 30"):
        load_task_file(write(tmp_path, BUMP))


def test_a_path_needs_a_surface_and_not_fields(tmp_path):
    job = "  path: {pattern: {kind: raster}}\n"
    with pytest.raises(ConfigError, match=r"config\.path: a path needs workpiece\.surface"):
        load_task_file(write(tmp_path, window_with("", job)))


def test_the_sphere_job_file_is_the_built_in_job():
    """models/tasks/raster_sphere.yaml and the surface-polishing task: the same path, start and commands."""
    task, config = load_task_file(TASKS / "raster_sphere.yaml")
    built_in = get_task("surface-polishing")
    reference = built_in.default_config()
    ours, theirs = build_path(task, config), build_path(built_in, reference)
    assert ours.length == pytest.approx(theirs.length, rel=1e-12) and ours.duration == pytest.approx(theirs.duration)
    np.testing.assert_allclose(ours.centres(), theirs.centres(), atol=1e-12)
    assert config.path == reference.path and config.gains == reference.gains and config.mode == reference.mode
    x = np.asarray(config.start.configuration)
    np.testing.assert_allclose(task.constraint_space(config).constraint.value(x),
                               built_in.constraint_space(reference).constraint.value(x), atol=1e-12)
