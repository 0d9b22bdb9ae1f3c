"""Polishing a sphere: the paper's Example 2.3 / 3-3 on a UR5e.

A rigid hydroelastic sphere (``models/sphere_workpiece.sdf``, radius 0.15 m)
stands in front of the UR5e; the compliant ball pad (radius 20 mm) presses on
it with the approach vector toward the centre, so the pad centre lies on the
sphere of radius rho = 0.17 m about the centre c. The constraint is (2.2-8),

    C = ((|P|^2 - rho^2) / (2 rho), two components of P x a),   P = p - c,

with the equator fix (drop the component k of P x a with the largest |a_k|)
and the first row scaled so that its force is the normal force in newtons
(force on the robot, outward: pressing with 10 N is F_d = (10, 0, 0)). Rows 2
and 3 fix the orientation (a along -P); a point contact does not enforce them
(it only pushes along the normal, through the pad's centre), so they are
kinematic rows: the controller holds them (C-ddot + 3 w_c C-dot + 2 w_c^2 C = 0),
with no force loop on them. The velocity-controlled coordinates are the
true-velocity rows of docs/theory.md §6 (Option A): the spin about a and the pad
centre's velocity along t_1 = e x P-hat and t_2 = t_1 x P-hat.

Task options (``task_options``):
  ``chart``: ``euler`` (z-x-z, the paper's r; singular at the poles) or
      ``pose`` (singularity-free, default).
  ``path``: ``latitude`` (an arc of the 45-degree latitude circle, e = e_z, the
      paper's t_1) or ``pole`` (a meridian through the north pole in the x-z
      plane, e = e_y so that t_1 stays regular there). With the Euler chart
      the pole path stops with ChartSingularityError where |sin(theta)| < 0.01.
  ``velocity_rows``: ``true`` (Option A, default) or ``paper`` (the paper's
      (3.3-11) E_p with the pseudo-velocity, naive: latitude path; it needs
      ``chart: euler``, and reading the options refuses it with another chart).
Task parameters: ``speed`` (m/s along the path), ``normal_force`` (N),
``start_angle`` (rad along the path from its start).
"""

import math

import numpy as np

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.charts import EulerZXZChart, PoseChart
from drake_hybrid.core.constraints import sphere_constraint
from drake_hybrid.core.kinematics import EndEffectorKinematics, inverse_kinematics
from drake_hybrid.core.projections import ConstraintSpace, sphere_paper_projection, sphere_true_velocity_projection
from drake_hybrid.station.arm import PAD_RADIUS
from drake_hybrid.station.parsing import ConfigureParser, add_model
from drake_hybrid.systems.sources import Profile, PseudoVelocitySource
from drake_hybrid.tasks.builtin.robots import UR5E_SEED, add_ur5e_with_pad
from drake_hybrid.tasks.config import ScenarioConfig, StartConfig
from drake_hybrid.tasks.pressing import pressing_positions
from drake_hybrid.tasks.task import Task
from drake_hybrid.tasks.task_options import SpherePolishingOptions

SPHERE_RADIUS = 0.15                       # m, models/sphere_workpiece.sdf
SPHERE_CENTER = np.array([0.45, 0.0, 0.10])
CONSTRAINT_RADIUS = SPHERE_RADIUS + PAD_RADIUS
LATITUDE = math.pi / 4                      # colatitude of the latitude path
PATHS = {
    # path: (axis e of the tangent rows, start unit vector P-hat(s) as a function of the arc angle s)
    "latitude": ((0.0, 0.0, 1.0), lambda s: np.array([math.sin(LATITUDE) * math.cos(math.pi - 0.8 + s),
                                                      math.sin(LATITUDE) * math.sin(math.pi - 0.8 + s),
                                                      math.cos(LATITUDE)])),
    "pole": ((0.0, 1.0, 0.0), lambda s: np.array([math.sin(-0.5 + s), 0.0, math.cos(-0.5 + s)])),
}


class SpherePolishing(Task):
    Options = SpherePolishingOptions
    name = "sphere-polishing"
    continuous_plant = True
    description = "UR5e polishing a sphere along a latitude arc or across the pole (Example 2.3)"
    camera = ((0.75, -0.55, 0.5), (0.3, 0.0, 0.25))   # Meshcat view (position, target; m): the arm and the sphere

    def base_config(self, options):
        return ScenarioConfig(
            task=self.name,
            mode="velocity-force",
            duration=3.0,
            gains=HybridGains(velocity=[10.0, 20.0, 20.0], position=[16.0, 64.0, 64.0],
                              force_proportional=[0.5, 0.0, 0.0], force_integral=[15.0, 1.0, 1.0],
                              constraint_frequency=15.0),
            desired_velocity=Profile(kind="constant", value=[]),   # empty: the path's command (see make_source)
            desired_force=Profile(kind="constant", value=[10.0, 0.0, 0.0]),     # press with 10 N
            start=StartConfig(in_contact=True, force_integral=[0.1, 0.0, 0.0]),
            task_parameters={"speed": 0.05, "start_angle": 0.0},
            task_options={"chart": "pose", "path": "latitude", "velocity_rows": "true"},
        )

    def labels(self, config=None):
        if config is not None and self.options(config).velocity_rows == "paper":
            # (3.3-11)'s e_i = (t_i, beta_i, 0): t_i . p-dot (m/s) plus beta_i . (phi-dot, theta-dot), beta_i
            # in 1/m: the paper's pseudo-velocity mixes units (docs/theory.md §6). Its error e_p' = E_t r-dot -
            # r-dot_td is the true rows' (PseudoVelocitySource): the summary's rows.
            velocity = {"velocity": ["psi-dot (spin)", "pseudo-velocity e_2 . r-dot", "pseudo-velocity e_3 . r-dot"],
                        "velocity_units": "rad/s | m/s + rad/m/s | m/s + rad/m/s",
                        "velocity_error": ["psi-dot (spin)", "t_1 . p-dot, through the paper's pseudo-velocity row",
                                           "t_2 . p-dot, through the paper's pseudo-velocity row"],
                        "velocity_error_units": "rad/s | m/s | m/s"}
        else:
            velocity = {"velocity": ["spin about a", "t_1 . p-dot", "t_2 . p-dot"],
                        "velocity_units": "rad/s | m/s | m/s"}
        return {**velocity,
                "force": ["normal force", "orientation row 1", "orientation row 2"], "force_units": "N | N | N",
                "constraint_units": "m",
                "constraint_note": "C_1: the compliant contact's compression while the pad presses (a steady "
                                   "offset); C_2, C_3: the orientation rows, held by the controller (a point "
                                   "contact cannot hold them)",
                # Measured on the default runs: 13.5 Hz at 0.035 m/s (latitude), 24 Hz at 0.05 m/s (pole).
                "force_note": "The ripple of 1e-4 to 1e-3 N once the start has decayed (about 0.01 % of the "
                              "command) repeats every 2-2.6 mm of the pad's travel, as its contact crosses the "
                              "facets of the tessellated sphere and pad (3 mm mesh resolution; docs/drake_notes.md)"}

    # -- options ----------------------------------------------------------------------------------
    def chart(self, config):
        return EulerZXZChart() if self.options(config).chart == "euler" else PoseChart()

    def path(self, config):
        return self.options(config).path

    # -- models -----------------------------------------------------------------------------------
    def add_robot(self, plant, config):
        return add_ur5e_with_pad(plant)

    def add_workpiece(self, plant, config):
        parser = Parser(plant)
        ConfigureParser(parser)
        sphere = add_model(parser, "sphere_workpiece.sdf")[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("sphere", sphere), RigidTransform(SPHERE_CENTER))
        return list(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("sphere", sphere)))

    # -- task geometry ----------------------------------------------------------------------------
    def constraint_space(self, config):
        chart = self.chart(config)
        constraint = sphere_constraint(chart, center=SPHERE_CENTER, radius=CONSTRAINT_RADIUS, form="paper",
                                       dropped_component="auto", force_in_newtons=True)
        return ConstraintSpace(constraint, self.velocity_projection(config, chart))

    def velocity_projection(self, config, chart):
        if self.options(config).velocity_rows == "paper":
            return sphere_paper_projection(chart, center=SPHERE_CENTER, radius=CONSTRAINT_RADIUS)
        axis, _ = PATHS[self.path(config)]
        return sphere_true_velocity_projection(chart, center=SPHERE_CENTER, radius=CONSTRAINT_RADIUS, axis=axis)

    def true_velocity_command(self, config):
        """The path's command in true-velocity coordinates: constant along both paths."""
        speed = self.options(config).speed
        if self.path(config) == "latitude":
            return [0.0, speed * math.sin(LATITUDE), 0.0]       # t_1 . p-dot = speed |t_1|, t_2 . p-dot = 0
        return [0.0, speed, 0.0]                                 # |t_1| = 1 on the meridian

    def make_source(self, config, controller_plant, robot, constraint_space):
        # An empty desired_velocity means "the path's own command" (see true_velocity_command).
        velocity = config.desired_velocity
        if not velocity.value:
            velocity = Profile(kind="constant", value=self.true_velocity_command(config))
        if self.options(config).velocity_rows == "paper":
            chart = constraint_space.chart
            axis, _ = PATHS[self.path(config)]
            true_rows = sphere_true_velocity_projection(chart, center=SPHERE_CENTER, radius=CONSTRAINT_RADIUS,
                                                        axis=axis)
            return PseudoVelocitySource(controller_plant, robot.end_effector_frame, robot.end_effector_point,
                                        constraint_space.velocity_projection, true_rows, velocity,
                                        config.desired_force, constraint_space.force_size)
        return super().make_source(config.replace(desired_velocity=velocity), controller_plant, robot,
                                   constraint_space)

    def run_notes(self, scenario, log, design_time_constant):
        """With the paper's (3.3-11) rows (``velocity_rows=paper``): how far the pad's t_1 . p-dot ends from
        its command, and why (docs/theory.md §6: the naive pseudo-velocity drops the unmeasurable Euler-angle
        accelerations, so the designed loop is not realized; the Li & Sastry law only, as the crank's note)."""
        if scenario.config.controller != "li-sastry" or "true_desired_velocity" not in log:
            return []
        t = log["t"]
        command, error = float(log["true_desired_velocity"][-1, 1]), float(log["velocity_error"][-1, 1])
        if command == 0:
            return []
        side = "short of" if error * command < 0 else "above"
        return [f"with the paper's (3.3-11) E_p and its pseudo-velocity (naive), t_1 . p-dot ends "
                f"{100 * abs(error / command):.0f} % {side} its {abs(command):.3g} m/s command after "
                f"{t[-1] - t[0]:.2g} s: the controller is fed pseudo-velocity rows, t_i . p-dot (m/s) plus "
                "beta_i . (phi-dot, theta-dot) (rad/s, beta_i in 1/m), whose desired acceleration needs the "
                "unmeasurable Euler-angle accelerations; dropping them leaves the designed loop unrealized "
                "(docs/theory.md §6; compare --option velocity_rows=true)"]

    # -- start ------------------------------------------------------------------------------------
    def pad_pose(self, config, arc_angle, depth=0.0):
        """Pose of the pad centre on the path at ``arc_angle``, ``depth`` m into the sphere, a = -P-hat."""
        _, start = PATHS[self.path(config)]
        P_hat = start(arc_angle)
        a = -P_hat
        x = np.cross([0.0, 1.0, 0.0], a) if self.path(config) == "latitude" else np.array([0.0, 1.0, 0.0])
        x = x - (x @ a) * a
        x /= np.linalg.norm(x)
        R = RotationMatrix(np.column_stack([x, np.cross(a, x), a]))
        return RigidTransform(R, SPHERE_CENTER + (CONSTRAINT_RADIUS - depth) * P_hat)

    def start_positions(self, scenario):
        config = scenario.config
        plant = scenario.controller_plant
        context = plant.CreateDefaultContext()
        kinematics = EndEffectorKinematics(plant, scenario.robot.end_effector_frame, np.zeros(3), PoseChart())
        start_angle = self.options(config).start_angle
        seed = [inverse_kinematics(kinematics, context, self.pad_pose(config, start_angle), UR5E_SEED)]

        def positions_at_depth(depth):
            seed[0] = inverse_kinematics(kinematics, context, self.pad_pose(config, start_angle, depth), seed[0])
            return seed[0]

        if not config.start.in_contact:
            return positions_at_depth(-config.start.gap)
        return pressing_positions(scenario, positions_at_depth)

