"""A flat compliant disc (station.tools): mounted from Python and from a task file, its contact material, the
constraint's orientation rows force-controlled (core.constraints.with_force_rows), the real workpiece off the
model (core.surface_moves, ModelErrorConfig.workpiece_*), and the contact patch measured against its
hydroelastic pressure (systems.contact_patch): each against its geometry, fast. The disc's press on a plane
the model gets wrong is tests/test_disc_runs.py (slow); its other runs and the linearizations are
docs/disc.py's (docs/disc.md)."""

import math
from pathlib import Path

import airo_models
import numpy as np
import pytest

from pydrake.geometry import Box, Cylinder, HydroelasticContactRepresentation, Role
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid import PoseChart
from drake_hybrid.core.constraints import sphere_constraint, with_force_rows
from drake_hybrid.core.errors import ArgumentError, ConfigError, PathError
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface
from drake_hybrid.core.kinematics import EndEffectorKinematics, inverse_kinematics
from drake_hybrid.core.surface_moves import moved_surface, surface_error_pose
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, SphereSurface
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.station.contact import ContactConfig, apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.path_config import PathConfig
from drake_hybrid.station.tools import STEM_LENGTH, ToolConfig
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.contact_patch import PATCH_FIELDS, patch_figures, pressure_samples
from drake_hybrid.tasks.builtin.robots import add_ur5e_with_pad
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task_file import load_task_file

MODELS = Path(__file__).resolve().parents[1] / "models" / "tasks"
DISC = ToolConfig(kind="disc", radius=0.025, thickness=0.01, modulus=3.0e5, resolution=0.003)
COLUMN = {name: index for index, name in enumerate(PATCH_FIELDS)}


# -- the tool ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("change, message", [
    (dict(kind="cone"), r"tool.kind must be one of ball, disc, got 'cone'"),
    (dict(orientation="loose"), r"tool.orientation must be held or force"),
    (dict(kind="disc", radius=-0.01), r"tool.radius must be a finite number > 0 and at most 0.5 \(m\)"),
    (dict(kind="disc", thickness=0.08), r"tool.thickness must be a finite number > 0 and at most 0.05 \(m\)"),
    (dict(kind="disc", modulus=math.inf), r"tool.modulus must be a finite number > 0"),
    (dict(radius=0.03), r"tool.radius is a disc's; the ball pad is models/pad_tool.sdf's"),
    (dict(kind="disc", radius="wide"), r"tool.radius"),
])
def test_a_bad_tool_is_a_one_line_config_error_naming_the_field(change, message):
    with pytest.raises(ConfigError, match=message) as raised:
        ToolConfig(**change).validate()
    assert "\n" not in str(raised.value)


def test_the_tools_offsets_and_orientation_rows():
    assert ToolConfig().offset == 0.02 and ToolConfig().orientation_rows == "held"
    assert DISC.offset == 0.0 and DISC.orientation_rows == "force"
    assert ToolConfig(kind="disc", orientation="held").orientation_rows == "held"


def _plant_with_disc(tool=DISC, contact=None, tilt=0.0, depth=0.0005):
    """A UR5e with ``tool`` pressed ``depth`` into a plane at z = 0.1, turned ``tilt`` rad about its x axis
    about the face's centre (the plant's own context; no controller)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(0.0), builder)
    robot = add_ur5e_with_pad(plant, tool=tool)
    workpiece = add_rigid_workpiece(plant, Box(0.3, 0.3, 0.04), RigidTransform([0.45, 0.0, 0.08]))
    apply_contact_defaults(plant, scene_graph, robot, workpiece, contact)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    # Pose the tool by moving the arm's joints with inverse kinematics on the plant itself.
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, np.zeros(3), PoseChart())
    R = RotationMatrix.MakeXRotation(tilt) @ RotationMatrix(np.array([[0.0, -1, 0], [-1, 0, 0], [0, 0, -1]]))
    q = inverse_kinematics(kinematics, plant_context, RigidTransform(R, [0.45, 0.0, 0.1 - depth]),
                           np.array([0.0, -1.9, 1.9, -1.6, -1.57, 0.0]))
    plant.SetPositions(plant_context, robot.arm, q)
    return plant, scene_graph, robot, plant_context


def test_mount_tool_puts_the_disc_face_at_the_controlled_point_with_its_own_material():
    plant = MultibodyPlant(0.0)
    robot = add_ur5e_with_pad(plant, tool=DISC)
    plant.Finalize()
    assert robot.tool == DISC and robot.end_effector_frame == "pad_center"
    frame = plant.GetFrameByName("pad_center")
    assert frame.GetFixedPoseInBodyFrame().translation() == pytest.approx([0.0, 0.0, STEM_LENGTH])
    plant, scene_graph, robot, _ = _plant_with_disc(contact=ContactConfig(pad_modulus=1e7, friction=0.2))
    inspector = scene_graph.model_inspector()
    (pad,) = robot.pad_geometries
    shape = inspector.GetShape(pad)
    assert isinstance(shape, Cylinder) and shape.radius() == 0.025 and shape.length() == 0.01
    properties = inspector.GetProximityProperties(pad)
    # The disc keeps its own modulus and mesh (not contact.pad_modulus, the ball's); friction is the config's.
    assert properties.GetProperty("hydroelastic", "hydroelastic_modulus") == 3.0e5
    assert properties.GetProperty("hydroelastic", "resolution_hint") == 0.003
    assert properties.GetProperty("material", "coulomb_friction").static_friction() == 0.2
    assert inspector.GetPoseInFrame(pad).translation() == pytest.approx([0.0, 0.0, STEM_LENGTH - 0.005])


def test_mount_tool_on_an_arm_of_your_own_takes_the_disc():
    plant = MultibodyPlant(0.0)
    arm = Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]
    robot = mount_tool(plant, arm, "tool0", tool=ToolConfig(kind="disc", radius=0.03), name="sander")
    assert robot.tool.radius == 0.03 and robot.end_effector_frame == "sander_center"
    with pytest.raises(ConfigError, match=r"mount_tool: tool.kind must be one of ball, disc"):
        mount_tool(plant, arm, "tool0", tool=ToolConfig(kind="brush"), name="brush")


# -- the patch ---------------------------------------------------------------------------------------

def _patch(plant, robot, plant_context, face_area):
    query = plant.get_geometry_query_input_port().Eval(plant_context)
    surfaces = query.ComputeContactSurfaces(HydroelasticContactRepresentation.kPolygon)
    X_WT = plant.GetFrameByName("pad_center").CalcPoseInWorld(plant_context)
    figures = patch_figures(surfaces, robot.pad_geometries, X_WT.translation(), X_WT.rotation().matrix()[:, 2],
                            face_area)
    return figures, pressure_samples(surfaces, robot.pad_geometries, X_WT)


def test_a_disc_pressed_flat_has_its_pressure_centred_even_over_its_face():
    depth = 0.0005
    plant, _, robot, plant_context = _plant_with_disc(depth=depth)
    face = math.pi * 0.025 ** 2
    figures, samples = _patch(plant, robot, plant_context, face)
    # The field rises from 0 on the disc's boundary to E at its mid-plane, half its thickness deep: p = E d / (h/2)
    # over the face, less within half a thickness of the rim (the mesh's field falls to 0 on the side).
    flat = 3.0e5 * depth / 0.005
    assert figures[COLUMN["cop_offset"]] < 1e-5
    assert figures[COLUMN["area_fraction"]] == pytest.approx(1.0, abs=0.02)
    assert figures[COLUMN["tilt"]] < 1e-5                               # the inverse kinematics solve
    assert figures[COLUMN["peak_pressure"]] == pytest.approx(flat, rel=1e-6)
    inner = np.linalg.norm(samples["points"][:, :2], axis=1) < 0.025 - 0.006
    assert samples["pressure"][inner] == pytest.approx(flat, rel=1e-6)
    assert figures[COLUMN["normal_force"]] == pytest.approx(figures[COLUMN["mean_pressure"]] * figures[COLUMN["area"]])
    assert 0.6 * flat < figures[COLUMN["mean_pressure"]] < flat


def test_a_tilted_disc_digs_in_with_its_rim_and_its_pressure_moves_off_the_axis():
    tilt = math.radians(2.0)
    plant, _, robot, plant_context = _plant_with_disc(tilt=tilt, depth=0.0005)
    figures, _ = _patch(plant, robot, plant_context, math.pi * 0.025 ** 2)
    assert figures[COLUMN["tilt"]] == pytest.approx(tilt, rel=1e-6)      # against the plane's own normal
    # 0.5 mm deep at the centre, the rim +-0.87 mm: the face touches where x > -0.57 R, 84 % of it.
    assert figures[COLUMN["area_fraction"]] == pytest.approx(0.84, abs=0.03)
    # The centre of pressure lies toward the rim that digs in: turned about +x, the face's -y side is the lower one.
    assert figures[COLUMN["cop_offset"]] > 0.005
    assert figures[COLUMN["cop_y"]] == pytest.approx(-figures[COLUMN["cop_offset"]], rel=1e-2)


def test_no_contact_is_nan_and_zeros():
    plant, _, robot, plant_context = _plant_with_disc(depth=-0.002)
    figures, samples = _patch(plant, robot, plant_context, 1.0)
    assert math.isnan(figures[COLUMN["cop_offset"]]) and figures[COLUMN["normal_force"]] == 0.0
    assert samples["pressure"].size == 0


# -- the moment rows ---------------------------------------------------------------------------------

def test_with_force_rows_releases_the_held_rows_and_keeps_the_compiled_constraint():
    chart = PoseChart()
    held = PlaneSurface([0.45, 0.0, 0.1], [0.0, 0.0, 1.0]).offset_constraint(chart, 0.0)
    assert held.kinematic_rows == (1, 2)
    moments = with_force_rows(held)
    assert moments.kinematic_rows == () and held.kinematic_rows == (1, 2)
    x = chart.configuration(RotationMatrix.MakeXRotation(np.pi).matrix(), np.array([0.45, 0.0, 0.1]))
    np.testing.assert_array_equal(moments.force_projection(x), held.force_projection(x))
    # At a disc lying flat the orientation rows' E_f are pure rotations about o_2 and -o_1: their force is the
    # moment about the controlled point (N m).
    E_f = moments.force_projection(x)
    R = RotationMatrix.MakeXRotation(np.pi).matrix()
    np.testing.assert_allclose(E_f[1], np.r_[0, 0, 0, R[:, 1]], atol=1e-12)
    np.testing.assert_allclose(E_f[2], np.r_[0, 0, 0, -R[:, 0]], atol=1e-12)
    assert with_force_rows(held, [2]).kinematic_rows == (1,)
    with pytest.raises(ArgumentError, match=r"rows \[0\] are not kinematic rows of constraint 'plane'"):
        with_force_rows(held, [0])
    paper = sphere_constraint(chart, form="paper")
    released = with_force_rows(paper)
    assert released.kinematic_rows == () and all(piece.kinematic_rows == () for piece in released.pieces)


# -- the model off the real workpiece ------------------------------------------------------------------

@pytest.mark.parametrize("surface", [
    PlaneSurface([0.45, 0.0, 0.1], [0.0, 0.0, 1.0]),
    SphereSurface([0.45, 0.0, 0.1], 0.15),
    CylinderSurface([0.45, 0.0, 0.0], [0.0, 1.0, 0.0], 0.1),
    HeightMapSurface(HeightMap(np.linspace(-0.05, 0.05, 11), np.linspace(-0.05, 0.05, 11),
                               0.01 * np.cos(np.linspace(-1, 1, 11))[None, :] * np.ones((11, 1))),
                     RigidTransform([0.45, 0.0, 0.1])),
])
def test_a_moved_surface_is_the_surface_moved(surface):
    X = surface_error_pose(8.0, [1.0, 1.0, 0.0], [0.45, 0.0, 0.1], [0.0, 0.0, -0.005])
    moved = moved_surface(surface, X)
    for p in ([0.46, 0.01, 0.12], [0.44, -0.012, 0.115]):
        q, n = surface.closest_point(p)
        q_moved, n_moved = moved.closest_point(X.multiply(np.asarray(p)))
        np.testing.assert_allclose(q_moved, X.multiply(q), atol=1e-7)
        np.testing.assert_allclose(n_moved, X.rotation().multiply(n), atol=1e-7)
    back = moved_surface(moved, X.inverse())
    np.testing.assert_allclose(back.closest_point([0.46, 0.01, 0.12])[0],
                               surface.closest_point([0.46, 0.01, 0.12])[0], atol=1e-7)


def test_the_pose_error_turns_about_the_pivot_and_shifts():
    X = surface_error_pose(8.0, [1.0, 0.0, 0.0], [0.45, 0.0, 0.1], [0.0, 0.0, -0.005])
    np.testing.assert_allclose(X.multiply([0.45, 0.0, 0.1]), [0.45, 0.0, 0.095], atol=1e-12)
    assert X.rotation().ToAngleAxis().angle() == pytest.approx(math.radians(8.0))
    with pytest.raises(PathError, match=r"surface_error_pose: axis must be a nonzero direction"):
        surface_error_pose(8.0, [0.0, 0.0, 0.0])
    with pytest.raises(PathError, match=r"moved_surface: surface must be a core.surfaces.Surface"):
        moved_surface(object(), X)


# -- configs and task files ---------------------------------------------------------------------------

@pytest.mark.parametrize("changes, message", [
    (dict(tool=DISC, contact=ContactConfig(pad_modulus=1e6)), r"contact.pad_modulus and contact.pad_resolution are "
                                                               r"the ball pad's; a disc has its own"),
    (dict(model_error_shift=[0.0, 0.005]), r"model_error.workpiece_shift must be \[x, y, z\]"),
    (dict(model_error_axis=[0.0, 0.0, 0.0]), r"model_error.workpiece_tilt_axis must be a nonzero direction"),
    (dict(model_error_tilt=120.0), r"model_error.workpiece_tilt must be within \[-90, 90\] deg"),
])
def test_bad_tool_and_workpiece_error_configs_are_refused_naming_the_field(changes, message):
    config = ScenarioConfig()
    for name, value in changes.items():
        if name.startswith("model_error_"):
            setattr(config.model_error, {"model_error_shift": "workpiece_shift", "model_error_axis":
                                         "workpiece_tilt_axis", "model_error_tilt": "workpiece_tilt"}[name], value)
        else:
            setattr(config, name, value)
    with pytest.raises(ConfigError, match=message):
        config.validate()


def test_a_task_that_mounts_its_own_ball_refuses_a_disc():
    config = get_task("sphere-polishing").default_config()
    config.tool = DISC
    with pytest.raises(ConfigError, match=r"tool.kind: task 'sphere-polishing' mounts its own tool \(the ball pad\)"):
        build_scenario(config, with_loggers=False)


@pytest.mark.slow                # builds the bump's disc station (its constraint compiled): tens of seconds
def test_surface_polishing_mounts_the_disc_its_moment_rows_and_the_model_off_the_real_part():
    task = get_task("surface-polishing")
    config = task.default_config({"workpiece": "bump"})
    config.tool = DISC
    config.model_error.workpiece_tilt = 5.0
    config.model_error.workpiece_shift = [0.0, 0.0, -0.003]
    config.path.moments = [0.05, -0.02]
    space = task.constraint_space(config)
    assert space.constraint.kinematic_rows == ()
    assert task.labels(config)["force"] == ["normal force", "moment about o_2", "moment about -o_1"]
    model, offset = task.workpiece_surface(config)
    real = task.real_workpiece_surface(config)
    assert offset == 0.0 and model is not real
    assert model.X_WM.rotation().ToAngleAxis().angle() == pytest.approx(math.radians(5.0))
    scenario = build_scenario(config)
    assert scenario.robot.tool.is_disc and scenario.patch is not None and "patch" in scenario.loggers
    # path.moments go to the moment rows of the path's force command (its first row the normal force).
    context = scenario.source.CreateDefaultContext()
    scenario.source.get_input_port(0).FixValue(context, np.zeros(12))
    scenario.source.get_contact_phase_input_port().FixValue(context, [2.0])
    force = scenario.source.GetOutputPort("desired_force").Eval(context)
    assert force[1:] == pytest.approx([0.05, -0.02])
    config.tool = ToolConfig(kind="disc", orientation="held")
    assert task.constraint_space(config).constraint.kinematic_rows == (1, 2)


def test_the_disc_task_files_load_with_force_controlled_orientation_rows():
    task, config = load_task_file(MODELS / "disc_plane.yaml", register=False)
    assert config.tool.is_disc and config.model_error.workpiece_tilt == 8.0
    space = task.constraint_space(config)
    assert space.constraint.kinematic_rows == ()
    model, offset = task.workpiece_surface(config)
    assert offset == 0.0
    # The model is the real plane turned by -8 deg: the controller's normal is 8 deg off the real one.
    assert math.degrees(math.acos(model.unit_normal @ task.real_workpiece_surface(config).unit_normal)) == \
        pytest.approx(8.0)
    config.tool = ToolConfig(kind="disc", orientation="held")
    assert task.constraint_space(config).constraint.kinematic_rows == (1, 2)


def test_a_disc_on_a_surface_offset_by_a_balls_radius_is_refused(tmp_path):
    text = (MODELS / "disc_plane.yaml").read_text().replace("offset: 0.0}", "offset: 0.02}")
    (tmp_path / "disc.yaml").write_text(text)
    task, config = load_task_file(tmp_path / "disc.yaml", register=False)
    with pytest.raises(ConfigError, match=r"workpiece.surface.offset is 0.02 m; a disc's controlled point is the "
                                          r"centre of its face"):
        task.constraint_space(config)


@pytest.mark.slow                # builds the bump's station up to the refusal: about 10 s
def test_path_moments_are_checked():
    """Two finite numbers, and only where the constraint has moment rows (their flow to the force command:
    ``test_surface_polishing_mounts_the_disc_its_moment_rows_and_the_model_off_the_real_part``)."""
    with pytest.raises(PathError, match=r"path.moments must be two finite numbers"):
        PathConfig(moments=[0.1]).validate()
    task = get_task("surface-polishing")
    config = task.default_config({"workpiece": "bump"})
    config.path.moments = [0.05, -0.02]
    config.tool = ToolConfig(kind="disc", orientation="held")
    with pytest.raises(ConfigError, match=r"path.moments: 2 given, but the constraint has 0 force-controlled rows"):
        build_scenario(config, with_loggers=False)


def test_a_held_jobs_patch_is_reported_at_its_end_and_a_lifted_one_before_the_lift():
    """``patch_report`` on logs shaped as a run's: a held path's ``path_done`` is 1 from its start (the
    disc's press jobs are held paths), which must not hide the whole run (every figure was None); the
    lift-off's samples (``lifting``) are left out of the end."""
    from drake_hybrid.experiments.patch_report import patch_report
    from drake_hybrid.systems.contact_patch import PATCH_FIELDS

    t = np.arange(0.0, 2.0, 0.01)
    patch = np.zeros((t.size, len(PATCH_FIELDS)))
    column = {name: i for i, name in enumerate(PATCH_FIELDS)}
    patch[:, column["normal_force"]] = 20.0
    patch[:, column["cop_offset"]] = np.where(t < 1.0, 2e-3, 1e-4)
    patch[:, column["area_fraction"]] = 0.97
    log = {"t": t, "patch": patch, "desired_force": np.full((t.size, 3), [20.0, 0.0, 0.0]),
           "force": np.full((t.size, 3), [20.0, 0.0, 0.0]), "path_done": np.ones((t.size, 1)),
           "path_progress": np.zeros((t.size, 3))}
    report = patch_report(log, design_time_constant=0.1, contact_time=0.2)
    assert report.final_cop_offset_mm == pytest.approx(0.1)
    assert report.max_cop_offset_mm_settled == pytest.approx(2.0)          # settled from 0.2 + 5 x 0.1 s
    assert report.final_area_fraction == pytest.approx(0.97) and report.final_normal_force == pytest.approx(20.0)
    lifting = (t >= 1.5).astype(float)[:, None]
    patch[t >= 1.5, column["cop_offset"]] = 9e-3
    report = patch_report(dict(log, patch=patch, lifting=lifting), design_time_constant=0.1, contact_time=0.2)
    assert report.final_cop_offset_mm == pytest.approx(0.1)
    assert report.max_cop_offset_mm_settled == pytest.approx(2.0)
