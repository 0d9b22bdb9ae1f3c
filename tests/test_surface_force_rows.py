"""The force row of every surface is the normal force in newtons where the pad is pressed in, and a held path is
an equilibrium wherever it is held (docs/paths.md).

* ``Surface.offset_constraint``'s first row is the signed distance (plane, sphere, cylinder exactly; a height
  map's to second order): a pure normal force at the pad centre, split by E^-T as the controller splits the
  measured wrench, reads as itself on the force row, on the offset surface and 0.8 or 2 mm inside it;
* a held path (``path.hold_at``) presses with the force the path commands there (by arc length, per waypoint),
  so ``linearize_continuous`` finds it an equilibrium with its designed eigenvalues at any h;
* in a user's diagram ``solve_contact_start`` pushes along the normal and turns the tool onto the held rows,
  so a pipe off its top line starts at rest; ``solve_approach_start`` puts the pad a gap above a pose for the
  guarded approach; a start turned off the held rows is named by ``linearize_at_contact``.
"""

import airo_models
import numpy as np
import pytest

from pydrake.geometry import Cylinder
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.analysis.linearization import linearize_at_contact, linearize_continuous
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import ArgumentError, NotAtEquilibriumError
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, SphereSurface, view_projection
from drake_hybrid.scenario.builder import prepare_config
from drake_hybrid.station.arm import mount_tool, robot_plant
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.contact_start import solve_approach_start, solve_contact_start
from drake_hybrid.station.loggers import add_loggers, read_log
from drake_hybrid.station.loop import add_hybrid_controller
from drake_hybrid.station.path_config import ForcePointConfig, PathConfig, PatternConfig, ViewConfig, WaypointConfig
from drake_hybrid.station.path_job import path_job
from drake_hybrid.station.start import prime_start
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.path_source import reference_rotation
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.path import build_path, with_path
from drake_hybrid.tasks.registry import get_task

PAD = 0.02
UR5E_GUESS = [0.0, -1.9, 1.9, -1.6, -1.57, 0.0]


def bump():
    """A 3 cm Gaussian bump (sigma 3 cm) on a 21 x 21 grid 8 mm apart."""
    x = y = np.linspace(-0.08, 0.08, 21)
    X, Y = np.meshgrid(x, y)
    return HeightMapSurface(HeightMap(x, y, 0.03 * np.exp(-(X ** 2 + Y ** 2) / (2 * 0.03 ** 2)), name="bump"),
                            RigidTransform([0.45, 0.0, 0.15]))


SURFACES = {
    "tilted plane": lambda: PlaneSurface([0.45, 0.0, 0.1], [np.sin(0.3), 0.0, np.cos(0.3)]),
    "sphere": lambda: SphereSurface([0.45, 0.0, 0.1], 0.15),
    "cylinder": lambda: CylinderSurface([0.45, 0.0, 0.1], [0.0, 1.0, 0.0], 0.1),
    "height map": bump,
}
# The largest relative misreading of the normal force allowed per surface, at 0.8 and 2 mm in: the analytic
# surfaces' signed distances read it to rounding; the height map's second-order distance to O((delta kappa)^2)
# (measured at these points of the bump: at most 4.7e-5 at 0.8 mm, 3.3e-4 at 2 mm; its first-order distance
# (Z - H) / sqrt(1 + |grad H|^2) alone read 2.1e-3 and 5.2e-3 there).
READING = {"tilted plane": (1e-12, 1e-12), "sphere": (1e-12, 1e-12), "cylinder": (1e-12, 1e-12),
           "height map": (1e-4, 5e-4)}


@pytest.mark.parametrize("name", SURFACES)
def test_the_force_row_reads_the_normal_force_where_the_pad_is_pressed_in(name):
    surface = SURFACES[name]()
    chart, view = PoseChart(), surface.default_view()
    space = ConstraintSpace(surface.offset_constraint(chart, PAD), view_projection(chart, view))
    worst = {0.0008: 0.0, 0.002: 0.0}
    for u, v in [(0.0, 0.0), (0.03, 0.02), (-0.04, 0.01), (0.02, -0.035)]:
        q, n = surface.lift(view, u, v)
        for depth in worst:
            p = q + (PAD - depth) * n
            R = reference_rotation(surface.held_normal(p, PAD), np.asarray(view.axis_u))
            x = chart.configuration(R, p)
            values = space.evaluate(x, np.zeros(6))
            normal = surface.closest_point(p)[1]                      # the contact's normal: the part's at q
            np.testing.assert_allclose(normal, n, atol=1e-9)
            force = space.split_wrench(values, chart.generalized_force(x, np.concatenate([np.zeros(3), 10 * normal])))
            worst[depth] = max(worst[depth], abs(force[1][0] - 10.0) / 10.0)
            C = np.asarray(space.constraint.value(x))
            np.testing.assert_allclose(C[1:], 0.0, atol=1e-12)        # the tool along the held normal
            assert C[0] == pytest.approx(-depth, abs=max(1e-12, 1e-3 * depth))   # the signed distance
    assert worst[0.0008] <= READING[name][0] and worst[0.002] <= READING[name][1], worst


def test_a_held_path_presses_with_the_force_it_commands_where_it_is_held():
    """By arc length and per waypoint: the start (with_path_commands) presses with F at the held point."""
    task = get_task("surface-polishing")
    config = task.default_config()
    length = build_path(task, config).length
    ramp = with_path(config, force_by_arc_length=[ForcePointConfig(0.0, 6.0), ForcePointConfig(length, 14.0)])
    for h in (0.0, 0.25, 1.0):
        prepared = prepare_config(with_path(ramp, hold_at=h))
        assert prepared.config.desired_force.evaluate(0.0)[0][0] == pytest.approx(6.0 + 8.0 * h, rel=1e-6)
    points = [WaypointConfig(list(np.array([0.45, 0.0, 0.1]) + 0.15 * np.array([np.sin(a), 0.0, np.cos(a)])), f)
              for a, f in ((0.0, 9.0), (0.1, 12.0), (0.2, 15.0))]
    held = with_path(config, pattern=type(config.path.pattern)(), waypoints=points, hold_at=1.0)
    assert prepare_config(held).config.desired_force.evaluate(0.0)[0][0] == pytest.approx(15.0)


@pytest.mark.parametrize("hold_at", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("name", SURFACES)
def test_a_held_paths_start_pose_is_at_rest_against_the_path_reference(name, hold_at):
    """``PathJob.pose_at_depth``: the approach vector where the held rows want it (along -held_normal) and no
    turn about it against the path's reference (``PathSource``'s spin row reads zero). On the height map the
    held normal (its second-order distance's gradient at the pad centre) is a few mrad off the map's normal;
    building the frame again from the heading turned it up to 0.7 mrad about the approach vector, which K_p
    pulled on: the UR10's held raster on the bump was refused as no equilibrium at h = 1 (max |x-dot| 0.143)."""
    surface = SURFACES[name]()
    settings = PathConfig(pattern=PatternConfig(kind="raster", size=[0.03, 0.015], spacing=0.015, center=[0.02, 0.01]),
                          force=10.0, view=ViewConfig(), hold_at=hold_at)
    job = path_job(surface, PAD, settings)
    X_WP, normal = job.start_pose()
    for depth in (-0.005, 0.0, 0.001):
        R = job.pose_at_depth(depth).rotation().matrix()
        held = surface.held_normal(job.pose_at_depth(depth).translation(), PAD)
        np.testing.assert_allclose(R[:, 2], -held, atol=1e-12)
        turn = R @ np.asarray(reference_rotation(normal, job.heading)).T
        spin = 0.5 * np.array([turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0], turn[1, 0] - turn[0, 1]]) @ R[:, 2]
        assert abs(spin) < 1e-12, spin


@pytest.mark.slow
@pytest.mark.parametrize("h", [0.25, 1.0])
def test_a_held_path_with_a_force_ramp_linearizes_to_its_design_anywhere(h):
    """The force by arc length from 6 N to 14 N: held at h, the continuous loop is at rest (it was refused for
    every h > 0, max |x-dot| 1.91 at 0.25 and 4.51 at 1) and every designed eigenvalue within 5 %."""
    task = get_task("surface-polishing")
    config = task.default_config()
    length = build_path(task, config).length
    config = with_path(config, force_by_arc_length=[ForcePointConfig(0.0, 6.0), ForcePointConfig(length, 14.0)],
                       hold_at=h)
    linear = linearize_continuous(config)
    assert linear.equilibrium_residual < 1e-5
    assert linear.match.matched and np.max(linear.match.relative_error) < 0.05, linear.match
    assert not linear.unstable_modes


# -- a user's own station -------------------------------------------------------------------------------

def add_robot(plant):
    arm = Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
    return mount_tool(plant, arm, "tool0")


PIPE = CylinderSurface(center=[0.45, 0.0, 0.1], axis=[0.0, 1.0, 0.0], radius=0.1)
GAINS = HybridGains(velocity=[30.0] * 3, position=[200.0] * 3, force_proportional=[0.5, 0.0, 0.0],
                    force_integral=[15.0, 1.0, 1.0], constraint_frequency=15.0)


def pipe_station(time_step, control_period, supervision=None):
    chart = PoseChart()
    space = ConstraintSpace(PIPE.offset_constraint(chart, PAD), view_projection(chart, PIPE.default_view()))
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(time_step), builder)
    robot = add_robot(plant)
    workpiece = add_rigid_workpiece(plant, Cylinder(0.1, 0.6), RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2),
                                                                               PIPE.center))
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=GAINS,
                                   mode="position-force", control_period=control_period,
                                   desired_velocity=Profile(value=[0.0, 0.0, 0.0]),
                                   desired_force=Profile(value=[8.0, 0.0, 0.0]), supervision=supervision,
                                   initial_phase=ContactPhase.APPROACH if supervision is not None else None)
    loggers = add_loggers(builder, hybrid) if control_period is not None else None
    return builder.Build(), hybrid, loggers


def off_top_pose(angle=np.radians(11.0)):
    """The pad centre on the pipe's pad-centre surface ``angle`` from its top line, the tool along -n
    (frame E's point P there)."""
    n = np.array([np.sin(angle), 0.0, np.cos(angle)])
    return RigidTransform(RotationMatrix(reference_rotation(n, [0.0, 1.0, 0.0])), PIPE.center + (0.1 + PAD) * n)


@pytest.mark.slow
def test_a_pipe_off_its_top_line_starts_at_rest_and_linearizes_to_its_design():
    """solve_contact_start pushes along the normal (11 deg from vertical) and keeps the held rows at zero (they
    ended 1.3e-3 off, max |x-dot| 0.72, when it pushed straight down); a start turned 1.5e-3 rad off them is named."""
    diagram, hybrid, _ = pipe_station(0.0, None)
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, off_top_pose(), UR5E_GUESS)
    controller_context = hybrid.controller.GetMyContextFromRoot(context)
    C = hybrid.controller.GetOutputPort("constraint_value").Eval(controller_context)
    np.testing.assert_allclose(C[1:], 0.0, atol=1e-9)
    F = hybrid.controller.GetOutputPort("force").Eval(controller_context)
    assert F[0] == pytest.approx(8.0, rel=1e-3)
    linear = linearize_at_contact(diagram, context, hybrid)
    # 7.5e-5 measured (3e-9 on the top line): off it the tessellated pipe's contact force is not exactly along the
    # analytic normal (the held rows read -4.5e-5 N m); the check allows 1 % of the state's size per second.
    assert linear.equilibrium_residual < 1e-3
    assert linear.match.matched and np.max(linear.match.relative_error) < 0.05, linear.match
    assert not linear.unstable_modes
    # The same start turned about the pad centre by 1.5 mrad: not at rest, and the held rows are named.
    plant = hybrid.plant
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = plant.GetPositions(plant_context, hybrid.robot.arm)
    q[-2] += 1.5e-3                                            # the wrist's second joint
    plant.SetPositions(plant_context, hybrid.robot.arm, q)
    prime_start(hybrid, context, np.zeros(6))
    with pytest.raises(NotAtEquilibriumError, match=r"the constraint's held rows are not zero at the start \(C\[1\]"):
        linearize_at_contact(diagram, context, hybrid)


@pytest.mark.slow
def test_an_approach_start_puts_the_pad_a_gap_above_the_pose_and_the_supervisor_lands_it():
    supervision = SupervisionConfig(approach_speed=0.02)
    diagram, hybrid, loggers = pipe_station(1e-3, 1e-3, supervision)
    context = diagram.CreateDefaultContext()
    solve_approach_start(diagram, context, hybrid, off_top_pose(), UR5E_GUESS, gap=0.005)
    controller_context = hybrid.controller.GetMyContextFromRoot(context)
    C = hybrid.controller.GetOutputPort("constraint_value").Eval(controller_context)
    assert C[0] == pytest.approx(0.005, abs=1e-9)              # 5 mm above, along the normal
    np.testing.assert_allclose(C[1:], 0.0, atol=1e-9)          # turned as the held rows want it
    Simulator(diagram, context).AdvanceTo(1.0)
    log = read_log(loggers, context)
    assert log["contact_phase"][-1, 0] == ContactPhase.CONTACT
    assert log["force"][-1, 0] == pytest.approx(8.0, rel=0.01)
    # Without a supervisor that approaches, the pad would start off the surface: refused.
    continuous, twin, _ = pipe_station(0.0, None)
    with pytest.raises(ArgumentError, match="solve_approach_start: systems has no contact supervisor that starts in "
                                            "APPROACH"):
        solve_approach_start(continuous, continuous.CreateDefaultContext(), twin, off_top_pose(), UR5E_GUESS)
