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
force on the robot is downward and F_d < 0 (spec section 0: "push up with
10 N" is F_d = -10).

Start (``start.configuration``): [x, theta] of the pad centre on the window.
Task parameters: ``window_height`` (m); ``joints`` (also a task option): 3 (default, the paper's
square case n = d) or 4 (``models/planar_4r.sdf``, a redundant arm n > d,
controlled with the dynamically consistent law and null-space damping).
"""

import math

import numpy as np

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser

from drake_hybrid.charts import PlanarChart
from drake_hybrid.constraints import window_constraint
from drake_hybrid.gains import HybridGains
from drake_hybrid.parsing import ConfigureParser, model_url
from drake_hybrid.projections import ConstraintSpace, GivenVelocityProjection
from drake_hybrid.sources import Profile, ProfileSource
from drake_hybrid.tasks.robots import PAD_CENTER_IN_TOOL, PAD_RADIUS, add_pad_tool

ARMS = {3: ("planar_3r.sdf", (1.0, 0.8, 0.3)), 4: ("planar_4r.sdf", (0.8, 0.7, 0.5, 0.2))}


class WindowWashing:
    name = "window-washing"
    continuous_plant = True
    description = "planar 3R arm wiping along a window pane while pressing on it (Example 2.1)"
    camera = ((0.8, -1.9, 0.7), (0.7, 0.0, 0.5))   # Meshcat view (position, target; m): facing the arm's plane

    def default_config(self, options=None):
        """The task's default ScenarioConfig; ``options`` update its task_options."""
        from drake_hybrid.scenarios import ScenarioConfig, StartConfig

        config = ScenarioConfig(
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
        config.task_options.update(options or {})
        return config

    def labels(self):
        """Plot labels of the velocity-controlled and force-controlled coordinates."""
        return {"velocity": ["x-dot", "theta-dot"], "velocity_units": "m/s | rad/s",
                "force": ["F (along E_f = [0 1 0])"], "force_units": "N", "constraint_units": "m"}

    # -- models --------------------------------------------------------------------------------
    def _arm(self, config):
        joints = int(config.task_options.get("joints", config.task_parameters.get("joints", 3)))
        if joints not in ARMS:
            raise ValueError(f"window-washing: task_parameters.joints must be 3 or 4, got {joints}")
        return joints, ARMS[joints]

    def add_robot(self, plant, config):
        from drake_hybrid.scenarios import RobotModel

        joints, (file_name, lengths) = self._arm(config)
        parser = Parser(plant)
        ConfigureParser(parser)
        arm = parser.AddModelsFromUrl(model_url(file_name))[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", arm))
        # Tool +z along the last link's +x, pad centre exactly at the tip.
        X_last_flange = RigidTransform(RotationMatrix.MakeYRotation(math.pi / 2),
                                       [lengths[-1] - PAD_CENTER_IN_TOOL, 0, 0])
        tool, weld, pad = add_pad_tool(plant, parser, plant.GetFrameByName(f"link{joints}", arm), X_last_flange)
        return RobotModel(arm=arm, model_instances=[arm, tool], end_effector_frame="tip",
                          end_effector_point=np.zeros(3), tool_weld=weld, pad_geometries=pad)

    def add_workpiece(self, plant, config):
        parser = Parser(plant)
        ConfigureParser(parser)
        window = parser.AddModelsFromUrl(model_url("window.sdf"))[0]
        height = self._height(config)
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("pane", window), RigidTransform([1.0, 0, height]))
        return list(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("pane", window)))

    # -- task geometry -------------------------------------------------------------------------
    def _height(self, config):
        return float(config.task_parameters.get("window_height", 1.0))

    def constraint_space(self, config):
        chart = PlanarChart()
        constraint = window_constraint(chart, height=self._height(config) - PAD_RADIUS)
        projection = GivenVelocityProjection(chart, [[1, 0, 0], [0, 0, 1]], name="E_p (3.3-1)")
        return ConstraintSpace(constraint, projection)

    def make_source(self, config, controller_plant, robot, constraint_space):
        return ProfileSource(config.desired_velocity, config.desired_force, constraint_space.velocity_size,
                             constraint_space.force_size)

    # -- start -----------------------------------------------------------------------------------
    @staticmethod
    def three_link_inverse_kinematics(lengths, x, y, theta):
        """q of a planar 3R chain with its tip at (x, y) and last-link angle theta (elbow below the wrist)."""
        L1, L2, L3 = lengths
        wx, wy = x - L3 * math.cos(theta), y - L3 * math.sin(theta)
        cos_q2 = (wx * wx + wy * wy - L1 * L1 - L2 * L2) / (2 * L1 * L2)
        if not -1 < cos_q2 < 1:
            raise ValueError(f"window-washing: the pad centre ({x:.3f}, {y:.3f}) at theta = {theta:.3f} is out of reach")
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
        from drake_hybrid.scenarios import pressing_positions

        config = scenario.config
        if len(config.start.configuration) != 2:
            raise ValueError(f"window-washing: start.configuration must be [x, theta], got {config.start.configuration}")
        x0, theta0 = config.start.configuration
        touching = self._height(config) - PAD_RADIUS

        def positions_at_depth(depth):
            return self.inverse_kinematics(config, x0, touching + depth, theta0)

        if not config.start.in_contact:
            return positions_at_depth(-0.01)
        return pressing_positions(scenario, positions_at_depth)
