"""Washing a window: the paper's Example 2.1 / 3-1 on a planar 3R arm.

The arm (``models/planar_3r.sdf``: 1.0, 0.8, 0.3 m; 2.0, 1.5, 0.5 kg) moves in
the vertical world x-z plane; the PlanarChart makes that plane the paper's
(x, y) with gravity along -y. A pad tool (compliant hydroelastic ball,
radius 20 mm) is welded at the tip; the controlled point is the pad's centre.
The window is a rigid hydroelastic pane whose lower face is the line
y = window_height (the paper's y = 1), so the pad centre is constrained to

    C(r) = y - (window_height - pad_radius) = 0,     E_f = [0 1 0]          (2.2-1)

and the velocity-controlled coordinates are r-dot_p = (x-dot, theta-dot),
E_p = [[1 0 0], [0 0 1]] (3.3-1). The robot presses up on the pane, so the
force on the robot is downward and F_d < 0 (docs/theory.md §0: "push up with
10 N" is F_d = -10).

Start (``start.configuration``): [x, theta] of the pad centre on the window.
Task parameters: ``window_height`` (m); ``joints`` (also a task option): 3 (default, the paper's
square case n = d) or 4 (``models/planar_4r.sdf``, a redundant arm n > d,
controlled with the dynamically consistent law and null-space damping);
``window_lift`` (m, default 0): the pane moves up by this much, starting at
``window_lift_time`` (s) over ``window_lift_duration`` (s), a cubic step with
zero end velocities (a surface that moves away: the contact is lost and must be
re-acquired; discrete plants only, the pane rides a prismatic joint driven by
a stiff PD actuator that SAP integrates implicitly). The controller's
constraint keeps the nominal height.
"""

import math

import numpy as np

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.tree import FixedOffsetFrame, PdControllerGains, PrismaticJoint
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.charts import PlanarChart
from drake_hybrid.core.constraints import window_constraint
from drake_hybrid.core.errors import ConfigError, UnreachablePoseError
from drake_hybrid.core.projections import ConstraintSpace, GivenVelocityProjection
from drake_hybrid.station.arm import PAD_CENTER_IN_TOOL, PAD_RADIUS, add_pad_tool
from drake_hybrid.station.parsing import ConfigureParser, add_model
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import ScenarioConfig, StartConfig
from drake_hybrid.tasks.pressing import pressing_positions
from drake_hybrid.tasks.task import Task
from drake_hybrid.tasks.task_options import WindowWashingOptions

ARMS = {3: ("planar_3r.sdf", (1.0, 0.8, 0.3)), 4: ("planar_4r.sdf", (0.8, 0.7, 0.5, 0.2))}
# PD gains of the moving pane's actuator (N/m, N s/m): with the pane's 1 kg, a 1 kHz natural frequency
# well damped, so the pane follows its lift profile to micrometres under a 10 N push.
LIFT_GAINS = (4.0e7, 1.2e4)


class WindowWashing(Task):
    Options = WindowWashingOptions
    name = "window-washing"
    continuous_plant = True
    description = "planar 3R arm wiping along a window pane while pressing on it (Example 2.1)"
    camera = ((0.8, -1.9, 0.7), (0.7, 0.0, 0.5))   # Meshcat view (position, target; m): facing the arm's plane

    def base_config(self, options):
        return ScenarioConfig(
            task=self.name,
            mode="velocity-force",
            duration=3.0,
            gains=HybridGains(velocity=[10.0, 8.0], position=[16.0, 12.0], force_proportional=0.5,
                              force_integral=15.0),
            desired_velocity=Profile(kind="constant", value=[0.1, 0.0]),     # 0.1 m/s along the pane
            desired_force=Profile(kind="constant", value=[-10.0]),           # press up with 10 N
            # xi(0) = 0.2 N s gives an initial force error -G xi(0) = -2 N so that the run shows the
            # designed force transient e_f(t) = -G exp(-G t) xi(0) (with xi(0) = 0 it is zero throughout).
            start=StartConfig(configuration=[0.9, math.pi / 2], in_contact=True, force_integral=[0.2]),
            task_parameters={"window_height": 1.0},
        )

    def labels(self, config=None):
        """Plot labels of the velocity-controlled and force-controlled coordinates."""
        return {"velocity": ["x-dot", "theta-dot"], "velocity_units": "m/s | rad/s",
                "force": ["F, along E_f = [0 1 0]"], "force_units": "N", "constraint_units": "m",
                "constraint_note": "C = y - h: the compliant contact's compression while the pad presses (a steady "
                                   "offset, not an error that grows); before contact, the gap"}

    # -- models --------------------------------------------------------------------------------
    def _arm(self, config):
        joints = self.options(config).joints
        if joints not in ARMS:
            raise ConfigError(f"task option 'joints' of task 'window-washing' must be 3 or 4, got {joints}")
        return joints, ARMS[joints]

    def add_robot(self, plant, config):
        joints, (file_name, lengths) = self._arm(config)
        parser = Parser(plant)
        ConfigureParser(parser)
        arm = add_model(parser, file_name)[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", arm))
        # Tool +z along the last link's +x, pad centre exactly at the tip.
        X_last_flange = RigidTransform(RotationMatrix.MakeYRotation(math.pi / 2),
                                       [lengths[-1] - PAD_CENTER_IN_TOOL, 0, 0])
        tool, weld, pad = add_pad_tool(plant, parser, plant.GetFrameByName(f"link{joints}", arm), X_last_flange)
        # Only the pad touches (the links' collision rods are for the start's clearance check).
        return RobotModel(arm=arm, model_instances=[arm, tool], end_effector_frame="tip",
                          end_effector_point=np.zeros(3), tool_weld=weld, pad_geometries=pad, only_pad_contact=True)

    def add_workpiece(self, plant, config):
        parser = Parser(plant)
        ConfigureParser(parser)
        window = add_model(parser, "window.sdf")[0]
        height = self._height(config)
        X_W_mount = RigidTransform([1.0, 0, height])
        pane_frame = plant.GetFrameByName("pane", window)
        if self._lift(config)[0] == 0:
            plant.WeldFrames(plant.world_frame(), pane_frame, X_W_mount)
        else:
            mount = plant.AddFrame(FixedOffsetFrame("window_mount", plant.world_frame(), X_W_mount))
            joint = plant.AddJoint(PrismaticJoint("window_lift", mount, pane_frame, [0.0, 0.0, 1.0]))
            actuator = plant.AddJointActuator("window_lift", joint, effort_limit=1.0e5)
            if plant.time_step() > 0:
                actuator.set_controller_gains(PdControllerGains(p=LIFT_GAINS[0], d=LIFT_GAINS[1]))
        return list(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("pane", window)))

    def _lift(self, config):
        """(lift, start time, duration) of the pane's motion."""
        options = self.options(config)
        lift, start, duration = options.window_lift, options.window_lift_time, options.window_lift_duration
        if lift != 0 and not (start > 0 and duration > 0):
            raise ConfigError(f"window-washing: window_lift_time and window_lift_duration must be positive, got "
                             f"{start}, {duration}")
        return lift, start, duration

    def connect_environment(self, builder, plant, config):
        """Drive the moving pane (``window_lift``) along its lift profile."""
        lift, start, duration = self._lift(config)
        if lift == 0:
            return
        if plant.time_step() == 0:
            raise ConfigError("window-washing: window_lift needs a discrete plant (time_step > 0): the pane is "
                             "driven by a PD actuator that only SAP integrates")
        profile = PiecewisePolynomial.CubicHermite([0.0, start, start + duration], [[0.0, 0.0, lift]],
                                                   [[0.0, 0.0, 0.0]])
        motion = builder.AddNamedSystem("window_motion", TrajectorySource(profile, output_derivative_order=1))
        builder.Connect(motion.get_output_port(),
                        plant.get_desired_state_input_port(plant.GetModelInstanceByName("window")))

    # -- task geometry -------------------------------------------------------------------------
    def _height(self, config):
        return self.options(config).window_height

    def constraint_space(self, config):
        chart = PlanarChart()
        constraint = window_constraint(chart, height=self._height(config) - PAD_RADIUS)
        projection = GivenVelocityProjection(chart, [[1, 0, 0], [0, 0, 1]], name="E_p (3.3-1)")
        return ConstraintSpace(constraint, projection)

    # -- start -----------------------------------------------------------------------------------
    @staticmethod
    def three_link_inverse_kinematics(lengths, x, y, theta):
        """q of a planar 3R chain with its tip at (x, y) and last-link angle theta (elbow below the wrist)."""
        L1, L2, L3 = lengths
        wx, wy = x - L3 * math.cos(theta), y - L3 * math.sin(theta)
        cos_q2 = (wx * wx + wy * wy - L1 * L1 - L2 * L2) / (2 * L1 * L2)
        if not -1 < cos_q2 < 1:
            raise UnreachablePoseError(f"window-washing: the pad centre ({x:.3f}, {y:.3f}) at theta = {theta:.3f} is "
                                       "out of reach")
        q2 = math.acos(cos_q2)
        q1 = math.atan2(wy, wx) - math.atan2(L2 * math.sin(q2), L1 + L2 * math.cos(q2))
        return np.array([q1, q2, theta - q1 - q2])

    def inverse_kinematics(self, config, x, y, theta):
        """Arm positions with the pad centre at (x, y) and tool angle theta. The 4R arm takes the
        3R solution of its last three links with its first joint pointing 0.35 rad above the target."""
        joints, (_, lengths) = self._arm(config)
        if joints == 3:
            return self.three_link_inverse_kinematics(lengths, x, y, theta)
        q1 = math.atan2(y, x) + 0.35
        ex, ey = lengths[0] * math.cos(q1), lengths[0] * math.sin(q1)
        rest = self.three_link_inverse_kinematics(lengths[1:], x - ex, y - ey, theta)
        return np.concatenate([[q1, rest[0] - q1], rest[1:]])

    def start_positions(self, scenario):
        config = scenario.config
        if len(config.start.configuration) != 2:
            raise ConfigError(f"window-washing: start.configuration must be [x, theta], got "
                              f"{config.start.configuration}")
        x0, theta0 = config.start.configuration
        touching = self._height(config) - PAD_RADIUS

        def positions_at_depth(depth):
            return self.inverse_kinematics(config, x0, touching + depth, theta0)

        if not config.start.in_contact:
            return positions_at_depth(-config.start.gap)
        return pressing_positions(scenario, positions_at_depth)
