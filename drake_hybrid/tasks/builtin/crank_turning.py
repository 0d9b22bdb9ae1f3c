"""Turning a crank: the paper's Example 2.2 / 3-2 on a UR5e.

``models/crank.sdf``: an arm of radius rho = 0.2 m turning about a vertical axis
(welded at c = (0.45, 0.2) and height b = 0.3 m) and, at its end, a handle that
spins about the radial axis pointing at the crank's axis. The UR5e's pad tool is
attached to the handle by a SAP weld constraint (discrete plant only), so the
pad centre is held on the circle with its approach vector toward the axis: the
inward branch of (2.2-5),

    C = (X^2 + Y^2 - rho^2, z - b, cos(theta), X cos(phi) + Y sin(phi)),   X = x - c_x, Y = y - c_y,

on the z-x-z Euler chart (theta = pi/2 here, far from its singularity). All four
rows are enforced by the environment (the weld), so all are force-controlled:
F = (radial, vertical, tilt, tangential/yaw) in the E_f of (3.3-2); the default
command is no radial force and a 5 N downward push along the crank's axis
(force on the robot +5 N along z). The velocity-controlled coordinates are the
true-velocity rows of docs/theory.md §6 (Option A, default): the spin psi-dot and the
crank rate alpha-dot = (-Y x-dot + X y-dot) / rho^2; or the paper's (3.3-6) E_p
with the pseudo-velocity (``task_options.velocity_rows = paper``, naive: its
r-ddot_pd drops the unmeasurable phi-ddot).

The force is measured by the wrist force/torque sensor (the weld joint between
tool0 and the tool): no port reports constraint forces.

Task options: ``velocity_rows`` (``true`` | ``paper``). Task parameters:
``start_angle`` (crank angle alpha at t = 0, rad).
"""

import math

import numpy as np

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.arguments import joint_rows
from drake_hybrid.core.charts import EulerZXZChart, PoseChart
from drake_hybrid.core.constraints import crank_constraint
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.kinematics import EndEffectorKinematics, inverse_kinematics
from drake_hybrid.core.projections import ConstraintSpace, crank_paper_projection, crank_true_velocity_projection
from drake_hybrid.station.arm import PAD_CENTER_IN_TOOL
from drake_hybrid.station.parsing import ConfigureParser, add_model
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.systems.sources import Profile, PseudoVelocitySource
from drake_hybrid.tasks.builtin.robots import add_ur5e_with_pad
from drake_hybrid.tasks.config import ScenarioConfig, StartConfig
from drake_hybrid.tasks.task import EigenvalueShift, Task
from drake_hybrid.tasks.task_options import CRANK_START_ANGLE, CrankTurningOptions

CRANK_RADIUS = 0.2                       # m, models/crank.sdf
# Placement and start chosen so that the UR5e stays away from its singularities along the turn: the
# worst condition number of J_g over the 1.5 rad of the default run is about 36 (docs/tasks.md);
# with the crank straight in front of the robot, the wrist passes its q5 = 0 singularity.
CRANK_CENTER = np.array([0.45, 0.2])
CRANK_HEIGHT = 0.3
START_ANGLE = CRANK_START_ANGLE          # rad, crank angle alpha at t = 0 (the option's default)
CRANK_SEED = np.array([0.0, -1.2, 1.8, -0.6, 1.57, 0.0])   # IK seed: the wrist branch with q5 near pi/2


def true_velocities(scenario, log, center=CRANK_CENTER, radius=CRANK_RADIUS):
    """(samples x 2) the true-velocity rows E_t r-dot (spin, crank rate; docs/theory.md §6) of every
    logged state of a crank run, whichever E_p the controller used (the crank's axis at ``center``,
    its radius ``radius``)."""
    true_rows = crank_true_velocity_projection(scenario.constraint_space.chart, center=center, radius=radius)
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    rates = []
    for q, v in zip(joint_rows(log["q"], "log['q']", "true_velocities", plant),
                    joint_rows(log["v"], "log['v']", "true_velocities", plant, kind="velocities")):
        plant.SetPositions(context, q)
        plant.SetVelocities(context, v)
        task = scenario.controller.kinematics.evaluate(context)
        rates.append(true_rows.matrix(task.configuration) @ task.velocity)
    return np.array(rates)


class CrankTurning(Task):
    Options = CrankTurningOptions
    name = "crank-turning"
    continuous_plant = False      # the SAP weld constraint needs a discrete plant
    description = "UR5e turning a crank whose handle it holds (weld constraint), pushing along its axis (Example 2.2)"
    camera = ((0.8, -0.6, 0.55), (0.3, 0.0, 0.22))     # Meshcat view (position, target; m): the arm and the crank

    def __init__(self, center=CRANK_CENTER, radius=CRANK_RADIUS, height=CRANK_HEIGHT, seed=CRANK_SEED):
        """The crank's axis at ``center`` (x, y; m), its handle circle of ``radius`` at ``height`` (m);
        ``seed``: the arm's joint positions inverse kinematics starts from. The defaults are the
        built-in task's (the crank task file, models/tasks/crank_turning.yaml, gives its own through
        the ``crank`` hook, tasks/hooks.py)."""
        self.center, self.radius, self.height = np.asarray(center, dtype=float), float(radius), float(height)
        self.seed = np.asarray(seed, dtype=float)

    def base_config(self, options):
        return ScenarioConfig(
            task=self.name,
            mode="velocity-force",
            duration=3.0,
            # A 1 kHz controller on a 2 kHz plant: with 1 ms SAP steps the stiff closed chain (arm, weld,
            # crank) has discretization modes near 18 and 31 Hz, lightly damped, which the force loop
            # excites while the crank turns (docs/drake_notes.md); with 0.5 ms steps they move out of
            # the way and the designed response appears.
            plant=MultibodyPlantConfig(time_step=5e-4, contact_model="hydroelastic",
                                       discrete_contact_approximation="sap"),
            control_period=1e-3,
            gains=HybridGains(velocity=[10.0, 10.0], position=[16.0, 16.0], force_proportional=0.5,
                              force_integral=15.0),
            sensor=WristSensorConfig(),
            desired_velocity=Profile(kind="constant", value=[0.0, 0.5]),          # psi-dot = 0, alpha-dot = 0.5 rad/s
            desired_force=Profile(kind="constant", value=[0.0, 5.0, 0.0, 0.0]),   # push down 5 N along the axis
            start=StartConfig(in_contact=True, force_integral=[0.0, 0.1, 0.0, 0.0]),
            task_parameters={"start_angle": START_ANGLE},
            task_options={"velocity_rows": "true"},
            # The paper's form on the velocity rows: the crank's F_v is the handle's and the tool's
            # inertia (the wrist sensor reads the tool the model already carries), which the
            # mechanism (``mechanism.source``) and the task's predictions describe; cancelling the
            # measured F_v would count the tool twice (control.law.tangential_compensation).
            compensate_tangential_force=False,
        )

    def labels(self, config=None):
        paper = config is not None and self._rows(config) == "paper"
        # The paper's row 2, -Y x-dot + X y-dot + phi-dot, adds m^2/s to rad/s: (rho^2 + 1) alpha-dot on the circle.
        # Its error e_p' = E_t r-dot - r-dot_td is alpha-dot's (PseudoVelocitySource): the summary's rows.
        crank_row = "pseudo-velocity (paper's E_p row 2, (3.3-8))" if paper else "alpha-dot (crank)"
        # Each force row is the multiplier of its row of C, so its unit is N m / (C's unit): row 1,
        # C_1 = X^2 + Y^2 - rho^2 in m^2, gives N/m, the radial force in N divided by |dC_1/dr| = 2 rho.
        errors = {"velocity_error": ["psi-dot (spin)", "alpha-dot (crank), through the paper's pseudo-velocity row"],
                  "velocity_error_units": "rad/s"} if paper else {}
        return {"velocity": ["psi-dot (spin)", crank_row], **errors,
                "velocity_units": "rad/s | m^2/s + rad/s" if paper else "rad/s",
                "force": ["radial / 2 rho (row 1)", "vertical", "tilt torque", "tangential/yaw (row 4)"],
                "force_units": "N/m | N | N m | N", "constraint_units": "m^2 | m | 1 | m",
                "constraint_note": "No contact: the pad is welded to the handle (a SAP weld constraint, compliant), "
                                   "so C is how far the weld gives under the force rows' loads",
                "force_note": "Row 1 is the multiplier of C_1 = X^2 + Y^2 - rho^2 (m^2), hence N/m: the radial force "
                              f"in N is 2 rho = {2 * self.radius:g} m times it. The 43 Hz ringing over the first "
                              "0.3 s is the closed loop's slowest non-designed mode (-25 +- 267j 1/s at the 0.5 ms plant step: arm, weld "
                              "and crank on the wrist sensor; docs/drake_notes.md), excited by the start's steps"}

    def _rows(self, config):
        return self.options(config).velocity_rows

    def start_angle(self, config):
        """The crank angle alpha at t = 0 (rad)."""
        return self.options(config).start_angle

    # -- models -----------------------------------------------------------------------------------
    def add_robot(self, plant, config):
        return add_ur5e_with_pad(plant)

    def add_workpiece(self, plant, config):
        if plant.time_step() == 0:
            raise ConfigError("crank-turning needs a discrete plant (time_step > 0): the tool is attached to the "
                             "handle by a SAP weld constraint, which continuous plants do not support")
        parser = Parser(plant)
        ConfigureParser(parser)
        crank = add_model(parser, "crank.sdf")[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("post", crank),
                         RigidTransform([self.center[0], self.center[1], self.height]))
        return self.weld_pad_to_handle(plant)

    @staticmethod
    def weld_pad_to_handle(plant):
        """The SAP weld constraint holding the pad centre (tool z = 0.05 m) on the handle frame of the
        crank (model instance ``crank``). Returns no geometries (the crank's are not the workpiece's)."""
        if plant.time_step() == 0:
            raise ConfigError("crank-turning needs a discrete plant (time_step > 0): the tool is attached to the "
                             "handle by a SAP weld constraint, which continuous plants do not support")
        tool = plant.GetBodyByName("tool")
        handle = plant.GetBodyByName("handle", plant.GetModelInstanceByName("crank"))
        plant.AddWeldConstraint(tool, RigidTransform([0, 0, PAD_CENTER_IN_TOOL]), handle, RigidTransform())
        return []

    # -- task geometry ----------------------------------------------------------------------------
    def constraint_space(self, config):
        chart = EulerZXZChart()
        constraint = crank_constraint(chart, radius=self.radius, height=self.height, center=self.center,
                                      form="paper")
        if self._rows(config) == "paper":
            return ConstraintSpace(constraint, crank_paper_projection(chart, center=self.center))
        return ConstraintSpace(constraint,
                               crank_true_velocity_projection(chart, center=self.center, radius=self.radius))

    def make_source(self, config, controller_plant, robot, constraint_space):
        if self._rows(config) == "paper":
            chart = constraint_space.chart
            true_rows = crank_true_velocity_projection(chart, center=self.center, radius=self.radius)
            return PseudoVelocitySource(controller_plant, robot.end_effector_frame, robot.end_effector_point,
                                        constraint_space.velocity_projection, true_rows, config.desired_velocity,
                                        config.desired_force, constraint_space.force_size)
        return super().make_source(config, controller_plant, robot, constraint_space)

    # -- start ------------------------------------------------------------------------------------
    def handle_pose(self, alpha):
        """Pose of the handle frame (= pad centre) at crank angle alpha, handle spin 0."""
        position = np.array([self.center[0] + self.radius * math.cos(alpha),
                             self.center[1] + self.radius * math.sin(alpha), self.height])
        # crank.sdf: handle = arm frame (rotated by alpha about z) then pitched by -pi/2 about y.
        R = RotationMatrix.MakeZRotation(alpha).multiply(RotationMatrix.MakeYRotation(-math.pi / 2))
        return RigidTransform(R, position)

    def start_positions(self, scenario):
        plant = scenario.controller_plant
        context = plant.CreateDefaultContext()
        kinematics = EndEffectorKinematics(plant, scenario.robot.end_effector_frame, np.zeros(3), PoseChart())
        alpha = self.start_angle(scenario.config)
        return inverse_kinematics(kinematics, context, self.handle_pose(alpha), self.seed)

    def velocity_row_inertia(self, plant, config, constraint_space):
        """I_v = G^T M_c G: the crank's (arm and spinning handle) inertia along the velocity rows at
        the start, for ``mechanism.source: plant`` (docs/baselines.md compares the laws on it).

        M_c is the crank's joint-space mass matrix (alpha, spin) in the simulation ``plant``; H maps
        its joint rates to the velocity rows, E_p nu of the handle frame (= the pad centre, with the
        tool's orientation) per unit joint rate, and G = H^-1 maps the rows back (along the crank
        the constraint rows are zero, so the rows determine the crank's motion)."""
        context = plant.CreateDefaultContext()
        crank = plant.GetModelInstanceByName("crank")
        plant.SetPositions(context, crank, [self.start_angle(config), 0.0])
        handle = plant.GetBodyByName("handle", crank)
        columns = plant.GetVelocitiesFromArray(crank, np.arange(plant.num_velocities())).astype(int)
        J_spatial = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, handle.body_frame(),
                                                      np.zeros(3), plant.world_frame(), plant.world_frame())
        chart = constraint_space.chart
        x = chart.configuration_of_pose(handle.EvalPoseInWorld(context))
        E_p = constraint_space.evaluate(x, np.zeros(chart.velocity_size)).velocity_projection
        H = np.column_stack([E_p @ chart.task_velocity(x, J_spatial[:, j]) for j in columns])
        G = np.linalg.inv(H)
        M_c = plant.CalcMassMatrix(context)[np.ix_(columns, columns)]
        return G.T @ M_c @ G

    # -- what the paper's massless crank leaves out --------------------------------------------------
    def eigenvalue_shifts(self, scenario, root_context):
        """The spin row's designed eigenvalues, moved by the handle's spin inertia I_h (the paper's
        constraint is massless; tests/test_six_dof.py checks these predictions within 2 %).

        With M_p the spin row's mobility (E J M^-1 J^T E^T): velocity/force has -K_v / (1 + M_p I_h)
        instead of -K_v; position/force has the roots of (1 + M_p I_h) s^2 + K_v s + K_p; in
        impedance/force the wrist sensor also reports the tool's own spin inertia I_t, which the law
        feeds forward: (1 + I_h + I_t - M_p I_t) s^2 + K_v s + K_p (M_p with the constraint rows held).
        These are the paper's form (``mechanism.source: none``, the default); with the mechanism's
        inertia in the law (``mechanism.source: plant``) or the tool's inertia compensated in the
        sensor, the design holds (tests/test_baselines.py) or no tested prediction applies: none given.
        """
        config = scenario.config
        compensated = getattr(config.sensor, "compensate_tool_inertia", False)
        if (config.controller != "li-sastry" or config.mechanism.source != "none"
                or (compensated and config.mode == "impedance-force")):
            return []
        controller = scenario.controller
        plant = scenario.controller_plant
        context = plant.CreateDefaultContext()
        arm_positions = scenario.plant.GetPositions(scenario.plant.GetMyContextFromRoot(root_context),
                                                    scenario.robot.arm)
        plant.SetPositions(context, arm_positions)
        task = controller.kinematics.evaluate(context)
        values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
        mobility = task.jacobian @ np.linalg.solve(plant.CalcMassMatrix(context), task.jacobian.T)
        I_h = scenario.plant.GetBodyByName("handle").default_rotational_inertia().get_moments()[2]
        gains = controller.validated_gains()
        K_v = float(gains.velocity[0, 0])
        if not controller.mode.integrates_position:
            M_p = float((values.velocity_projection @ mobility @ values.velocity_projection.T)[0, 0])
            return [EigenvalueShift(-K_v, -K_v / (1.0 + M_p * I_h),
                                    f"spin row slowed by the handle's spin inertia I_h = {I_h:.3g} kg m^2 "
                                    f"(massless in the paper): -K_v / (1 + M_p I_h), M_p = {M_p:.3g}; mechanism: {{source: plant}} puts it in the law")]
        A = values.matrix @ mobility @ values.matrix.T
        k = scenario.constraint_space.velocity_size
        M_p = float((A[:k, :k] - A[:k, k:] @ np.linalg.solve(A[k:, k:], A[k:, :k]))[0, 0])
        K_p = float(gains.position[0, 0])
        if controller.mode.value == "position-force":
            factor = 1.0 + M_p * I_h
            reason = (f"spin pair moved by the handle's spin inertia I_h = {I_h:.3g} kg m^2 (massless in the "
                      f"paper): roots of (1 + M_p I_h) s^2 + K_v s + K_p, M_p = {M_p:.3g}; mechanism: {{source: plant}} puts it in the law")
        else:
            I_t = scenario.plant.GetBodyByName("tool").default_rotational_inertia().get_moments()[2]
            if np.count_nonzero(gains.impedance_mass[0, 1:]):
                return []            # an impedance mass coupling the spin row to others: no one-row prediction
            inverse_mass = float(gains.impedance_inverse_mass[0, 0])     # 1: the paper's unit mass
            factor = 1.0 + inverse_mass * (I_h + I_t) - M_p * I_t
            reason = (f"spin pair moved by the handle's inertia I_h = {I_h:.3g} and the tool's I_t = {I_t:.3g} "
                      f"kg m^2 in the wrist sensor's reading, fed forward: roots of (1 + M_d^-1 (I_h + I_t) - M_p "
                      f"I_t) s^2 + K_v s + K_p, M_p = {M_p:.3g}, M_d^-1 = {inverse_mass:.3g}; mechanism: "
                      f"{{source: plant}} puts it in the law")
        designed = np.sort_complex(np.roots([1.0, K_v, K_p]).astype(complex))
        predicted = np.sort_complex(np.roots([factor, K_v, K_p]).astype(complex))
        return [EigenvalueShift(d, p, reason) for d, p in zip(designed, predicted)]

    def run_notes(self, scenario, log, design_time_constant):
        """The true crank rate's deviation from the designed e^(-K_v t) (docs/theory.md §6): with the
        paper's E_p (``velocity_rows=paper``) the controlled rows are pseudo-velocities, so the summary's
        rows do not show what the crank itself does; this figure compares the two options (the
        Li & Sastry law only: a baseline has no such design)."""
        if scenario.config.controller != "li-sastry":
            return []
        rates = true_velocities(scenario, log, self.center, self.radius)[:, 1]
        t = log["t"]
        # The true-velocity command (the paper's rows get it converted to a pseudo-velocity).
        command = np.array([scenario.config.desired_velocity.evaluate(float(time))[0][1] for time in t])
        error = np.array(rates) - command
        K_v = float(scenario.controller.validated_gains().velocity[1, 1])
        deviation = float(np.max(np.abs(error - np.exp(-K_v * (t - t[0])) * error[0])))
        rows = "true-velocity rows (Option A)" if self._rows(scenario.config) == "true" else \
            "the paper's E_p with its pseudo-velocity (naive)"
        return [f"with {rows}, the true crank rate's error deviates at most {deviation:.2e} rad/s from the designed "
                f"e^(-K_v t) (compare --option velocity_rows={'paper' if rows.startswith('true') else 'true'})"]

    def set_environment_state(self, scenario, plant_context):
        """The crank at the start angle, the handle unspun, both at rest."""
        plant = scenario.plant
        crank = plant.GetModelInstanceByName("crank")
        plant.SetPositions(plant_context, crank, [self.start_angle(scenario.config), 0.0])
        plant.SetVelocities(plant_context, crank, [0.0, 0.0])
