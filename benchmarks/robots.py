"""The benchmark controllers: one HybridController per robot, at a fixed state and fixed inputs.

Each ``BenchmarkRobot`` holds the controller's own (continuous, float) plant, a
continuous ``HybridController`` on it, a nominal state [q; v] on the task's
constraint with a velocity along the task, and constant values for every
input port. Drake's ``InverseDynamicsController`` is built on the very same
plant for comparison (``make_inverse_dynamics_controller``).

Robots:

``planar-3r``
    the window-washing task as the package builds it (``get_task("window-washing")``,
    ``scenarios.build_controller_plant``): n = d = 3, m = 1.
``ur5e``
    the UR5e of ``airo-models`` (base welded, end effector ``tool0`` plus a 5 cm tool
    point) on a sphere of radius 0.2 m: ``surface_constraint`` on a ``PoseChart``
    (m = 3 rows: the surface and the two normal rows) with a ``KernelVelocityProjection``
    anchored at the start pose. n = d = 6.
``panda``
    the Franka Panda of ``example-robot-data`` (fingers welded, one actuator per arm
    joint added), same sphere task: n = 7 > d = 6, the dynamically consistent law.

``surface_rows_controller`` builds the UR5e or Panda controller with m = 1..5 generic
constraint rows (for the scaling table).
"""

import importlib.metadata
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import sympy

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JointIndex, RevoluteJoint
from pydrake.systems.controllers import InverseDynamicsController

from drake_hybrid import Constraint, ConstraintSpace, KernelVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.control import fast_compile
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.kinematics import EndEffectorKinematics, inverse_kinematics
from drake_hybrid.tasks.plant import build_controller_plant
from drake_hybrid.tasks.registry import get_task

# The benchmarks time the compiled law: every controller compiles (or loads) it at its first tick, in this
# process, instead of running the generic law while a background job compiles it (control/fast_compile.py).
fast_compile.set_policy("foreground")

SPHERE_CENTER = np.array([0.45, 0.10, 0.10])     # m, in the arm's base (world) frame
SPHERE_RADIUS = 0.20                             # m
START_TILT = 0.3                                 # rad: start point 0.3 rad from the sphere's top, in x-z
TOOL_POINT = np.array([0.0, 0.0, 0.05])          # p_EP: 5 cm along the flange's z axis
PRESSING_FORCE = 10.0                            # N, on the workpiece (the robot feels -10 N along the normal)
TANGENTIAL_SPEED = 0.1                           # m/s, the start velocity along the surface


@dataclass
class BenchmarkRobot:
    """A controller at one state, ready to evaluate."""

    name: str
    description: str
    plant: object                  # the controller's continuous float MultibodyPlant
    controller: object             # continuous HybridController (actuation is direct feedthrough)
    state: np.ndarray              # nominal [q; v]
    inputs: dict = field(default_factory=dict)     # input port name -> constant value

    @property
    def joints(self):
        return self.plant.num_velocities()

    @property
    def force_rows(self):
        return self.controller.force_size

    @property
    def task_size(self):
        return self.controller.task_size


# --------------------------------------------------------------------------------------------------
# Plants
# --------------------------------------------------------------------------------------------------

def ur5e_plant():
    """The UR5e of airo-models on a continuous MultibodyPlant, base welded. Returns (plant, frame name)."""
    import airo_models

    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    plant.Finalize()
    return plant, "tool0"


def panda_urdf_path():
    """panda.urdf of the example-robot-data wheel (a cmeel prefix in site-packages)."""
    distribution = importlib.metadata.distribution("example-robot-data")
    path = Path(distribution.locate_file("cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"))
    if not path.exists():
        raise FileNotFoundError(f"example-robot-data is installed but has no {path}")
    return path


def panda_plant():
    """The Franka Panda with its fingers welded (prismatic -> fixed) and an actuator on each arm joint.

    example-robot-data's panda.urdf has no transmissions, so Drake adds no actuators;
    the effort limits are the URDF's."""
    path = panda_urdf_path()
    share = path.parents[3]                                          # .../share/example-robot-data
    text = path.read_text()
    text = re.sub(r'type="prismatic"', 'type="fixed"', text)          # the two finger joints
    text = re.sub(r"<mimic[^>]*/>|<safety_controller[^>]*/>", "", text)
    effort_limits = dict(re.findall(r'<joint name="([^"]+)" type="revolute">.*?<limit effort="([^"]+)"', text, re.S))
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    parser.package_map().Add("example-robot-data", str(share))
    parser.AddModelsFromString(text, "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0"))
    for i in range(plant.num_joints()):
        joint = plant.get_joint(JointIndex(i))
        if isinstance(joint, RevoluteJoint):
            plant.AddJointActuator(f"{joint.name()}_actuator", joint, float(effort_limits[joint.name()]))
    plant.Finalize()
    return plant, "panda_hand_tcp"


# --------------------------------------------------------------------------------------------------
# Controllers
# --------------------------------------------------------------------------------------------------

def _sphere_start_pose():
    """The tool pose at the start: on the sphere, START_TILT from its top, approach vector to the centre."""
    normal = np.array([math.sin(START_TILT), 0.0, math.cos(START_TILT)])
    R = RotationMatrix.MakeYRotation(START_TILT).multiply(RotationMatrix.MakeXRotation(math.pi))
    assert np.allclose(R.matrix()[:, 2], -normal)
    return RigidTransform(R, SPHERE_CENTER + SPHERE_RADIUS * normal), normal


def _start_state(plant, frame, chart, q_guess, velocity_projection_rows=None):
    """q at the start pose (inverse kinematics) and v moving the tool point at TANGENTIAL_SPEED along y."""
    kinematics = EndEffectorKinematics(plant, frame, TOOL_POINT, chart)
    context = plant.CreateDefaultContext()
    X_start, _ = _sphere_start_pose()
    q = inverse_kinematics(kinematics, context, X_start, q_guess)
    plant.SetPositions(context, q)
    task = kinematics.evaluate(context)
    # nu = (v, omega) = (0, TANGENTIAL_SPEED, 0, 0, 0, 0): along the sphere's latitude at the start.
    nu = np.zeros(chart.velocity_size)
    nu[1] = TANGENTIAL_SPEED
    v = np.linalg.lstsq(task.jacobian, nu, rcond=None)[0]
    return q, v, task.configuration


def _spatial_inputs(controller, space, x, normal):
    k, m = controller.velocity_size, controller.force_size
    # The environment pushes the tool out along the normal: [n; f] at the tool point, world frame.
    wrench = np.concatenate([np.zeros(3), PRESSING_FORCE * normal])
    return {"measured_wrench": wrench,
            "desired_velocity": np.full(k, 0.05),
            "desired_acceleration": np.zeros(k),
            "desired_force": np.full(m, -PRESSING_FORCE / math.sqrt(m))}


def _arm(name):
    if name == "ur5e":
        plant, frame = ur5e_plant()
        q_guess = np.array([0.0, -1.9, 1.9, -1.57, -1.57, 0.0])
        description = "UR5e (airo-models 0.0.12), sphere surface constraint, PoseChart, kernel E_p"
    elif name == "panda":
        plant, frame = panda_plant()
        q_guess = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.785])
        description = "Franka Panda (example-robot-data 6.0.0), sphere surface constraint, PoseChart, kernel E_p"
    else:
        raise ValueError(f"unknown arm '{name}' (use 'ur5e' or 'panda')")
    return plant, frame, q_guess, description


def spatial_controller(name, mode="velocity-force", gains=None, control_period=None):
    """The UR5e or Panda on the sphere (surface_constraint, m = 3) with a kernel E_p anchored at the start."""
    plant, frame, q_guess, description = _arm(name)
    chart = PoseChart()
    q, v, x0 = _start_state(plant, frame, chart, q_guess)
    constraint = surface_constraint(
        chart, lambda p: sum((p[i] - SPHERE_CENTER[i]) ** 2 for i in range(3)) - SPHERE_RADIUS ** 2, name="sphere")
    space = ConstraintSpace(constraint, KernelVelocityProjection(constraint, anchor=x0))
    return _finish(name, description, plant, frame, space, q, v, x0, mode, gains, control_period)


def surface_rows_controller(name, rows, mode="velocity-force", control_period=None):
    """The UR5e or Panda with m = ``rows`` (1..5) constraint rows at the start pose:
    z = z0, a_x = a_x0, a_y = a_y0, x = x0, y = y0 (the first ``rows`` of them), kernel E_p."""
    plant, frame, q_guess, description = _arm(name)
    chart = PoseChart()
    q, v, x0 = _start_state(plant, frame, chart, q_guess)
    px, py, pz = chart.position
    a = chart.approach
    values = dict(zip(chart.configuration_symbols, x0))
    candidates = [pz, a[0], a[1], px, py]
    if not 1 <= rows <= len(candidates):
        raise ValueError(f"rows must be 1..{len(candidates)}, got {rows}")
    expressions = [e - sympy.Float(float(e.subs(values))) for e in candidates[:rows]]
    constraint = Constraint(chart, expressions, name=f"{rows} rows")
    space = ConstraintSpace(constraint, KernelVelocityProjection(constraint, anchor=x0))
    return _finish(f"{name} m={rows}", f"{description.split(',')[0]}, {rows} generic rows", plant, frame, space,
                   q, v, x0, mode, None, control_period)


def _finish(name, description, plant, frame, space, q, v, x0, mode, gains, control_period):
    controller = HybridController(plant, frame, TOOL_POINT, space, gains=gains or HybridGains(), mode=mode,
                                  control_period=control_period)
    _, normal = _sphere_start_pose()
    inputs = _spatial_inputs(controller, space, x0, normal)
    inputs["estimated_state"] = np.concatenate([q, v])
    return BenchmarkRobot(name=name, description=description, plant=plant, controller=controller,
                          state=np.concatenate([q, v]), inputs=inputs)


def planar_controller(mode="velocity-force", joints=3, control_period=None):
    """The window-washing task's controller, as the package builds it, at the task's start on the window."""
    task = get_task("window-washing")
    config = task.default_config()
    config.task_parameters = dict(config.task_parameters, joints=joints)
    plant, robot = build_controller_plant(task, config)
    space = task.constraint_space(config)
    controller = HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space,
                                  gains=config.gains, mode=mode, control_period=control_period)
    from drake_hybrid.station.arm import PAD_RADIUS

    x_start, theta_start = config.start.configuration
    q = task.inverse_kinematics(config, x_start, config.task_parameters["window_height"] - PAD_RADIUS, theta_start)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    task_kinematics = controller.kinematics.evaluate(context)
    nu = np.array([0.1, 0.0, 0.0])                                      # 0.1 m/s along the pane
    v = np.linalg.lstsq(task_kinematics.jacobian, nu, rcond=None)[0]
    k = controller.velocity_size
    inputs = {"estimated_state": np.concatenate([q, v]),
              # the pane pushes the pad down (world -z) with 10 N
              "measured_wrench": np.array([0, 0, 0, 0, 0, -10.0]),
              "desired_velocity": np.array(config.desired_velocity.value, dtype=float),
              "desired_acceleration": np.zeros(k),
              "desired_force": np.array(config.desired_force.value, dtype=float)}
    name = "planar-3r" if joints == 3 else f"planar-{joints}r"
    return BenchmarkRobot(name=name, description=f"planar {joints}R window washing (the package's task), PlanarChart",
                          plant=plant, controller=controller, state=inputs["estimated_state"], inputs=inputs)


ROBOTS = ("planar-3r", "planar-4r", "ur5e", "panda")


def make_robot(name, mode="velocity-force", control_period=None):
    """One of ROBOTS; ``control_period`` None gives the continuous controller (actuation = the law)."""
    if name == "planar-3r":
        return planar_controller(mode, control_period=control_period)
    if name == "planar-4r":
        return planar_controller(mode, joints=4, control_period=control_period)
    return spatial_controller(name, mode, control_period=control_period)


def make_inverse_dynamics_controller(plant, kp=100.0, ki=0.0, kd=20.0):
    """Drake's C++ InverseDynamicsController on ``plant`` (with a reference acceleration input,
    the feedforward our law also has)."""
    n = plant.num_velocities()
    return InverseDynamicsController(plant, np.full(n, kp), np.full(n, ki), np.full(n, kd), True)
