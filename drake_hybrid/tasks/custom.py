"""Your own robot and your own constraint in the closed loop, in a handful of lines.

The built-in tasks (``drake_hybrid.tasks.registry``) are recipes that ``build_scenario``
wires into plant -> sensor -> controller -> plant. ``CustomTask`` is the same
recipe made from pieces you pass in, so every scenario tool works on it
unchanged once it is registered by name::

    task = CustomTask("panda-drum", add_robot=add_panda, add_workpiece=add_drum,
                      constraint_space=space, start_pose=X_WP0, joint_guess=q_guess)
    register_task(task)
    result = simulate(task.default_config(desired_velocity=[0.05, 0, 0, 0, 0], desired_force=[10.0]))
    linearize_continuous(result.config)               # eigenvalues, as for the paper's tasks

The pieces:

* ``add_robot(plant) -> RobotModel``: parse your arm, weld its base, and attach
  a tool (``mount_tool`` attaches the compliant ball pad of
  ``models/pad_tool.sdf``). It is called twice: on the simulation plant (with a
  SceneGraph) and on the controller's own plant (without). Helpers for arms
  from URDF model packages: ``weld_joints`` (e.g. gripper fingers: the law
  needs one actuator per joint), ``add_actuators`` (URDFs without
  transmissions; effort limits from the URDF).
* ``add_workpiece(plant) -> geometry ids``: ``add_rigid_workpiece`` registers a
  rigid hydroelastic shape on the world body.
* ``constraint_space``: a ``ConstraintSpace`` (your chart, C and E_p).
* ``start_pose``: the end-effector pose with the controlled point on the
  constraint (touching, not pressing). The start that presses with F_d(0) is
  found as for the built-in tasks (``tasks.pressing.pressing_positions``): inverse
  kinematics from ``joint_guess`` at depths along the pressing direction
  -sum_i F_d,i grad_p C_i (the robot pushes the workpiece with -F_d).
"""

from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from pydrake.geometry import GeometryId
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.arguments import describe, function, instance, text, vector
from drake_hybrid.core.errors import ArgumentError, ConfigError, OffConstraintError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.kinematics import inverse_kinematics
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import ScenarioConfig, StartConfig
from drake_hybrid.tasks.pressing import pressing_positions
from drake_hybrid.tasks.task import Scenario, Task


class CustomTask(Task):
    """A task from your own robot, workpiece, constraint space and start (see the module docstring).

    Args:
        name: the task's name (``ScenarioConfig.task``; ``register_task`` makes it known).
        add_robot: ``add_robot(plant) -> RobotModel`` (see ``mount_tool``).
        add_workpiece: ``add_workpiece(plant) -> list of collision geometry ids``.
        constraint_space: a ConstraintSpace (chart, constraint C, velocity projection E_p).
        start_pose: RigidTransform of the end-effector frame, its controlled point on C = 0
            (``start.configuration`` stores it as [x, y, z, roll, pitch, yaw]).
        joint_guess: the arm's joint positions to start inverse kinematics from (redundant
            arms stay close to it).
        labels: plot labels ``{"velocity": [...], "velocity_units": ..., "force": [...],
            "force_units": ...}``.
        camera: Meshcat view for animations, (camera position, target) in world (m).
    """

    def __init__(self, name: str, add_robot: Callable[[MultibodyPlant], RobotModel],
                 add_workpiece: Callable[[MultibodyPlant], Iterable[GeometryId]], constraint_space: ConstraintSpace,
                 start_pose: RigidTransform, joint_guess: ArrayLike, labels: Optional[Dict[str, Any]] = None,
                 camera: Optional[Tuple[Sequence[float], Sequence[float]]] = None,
                 description: str = "a user-defined task") -> None:
        owner = "CustomTask"
        self.name = text(name, "name", owner)
        if not name.strip():
            raise ArgumentError(f"{owner}: name must be a non-empty string (the task's name in configs), got ''")
        self._add_robot = function(add_robot, "add_robot", owner, "add_robot(plant) -> RobotModel")
        self._add_workpiece = function(add_workpiece, "add_workpiece", owner,
                                       "add_workpiece(plant) -> list of collision geometry ids")
        if not all(hasattr(constraint_space, attribute) for attribute in ("chart", "constraint", "force_size",
                                                                         "velocity_size")):
            raise ArgumentError(f"{owner}: constraint_space must be a ConstraintSpace (chart, constraint C, velocity "
                                f"projection E_p), got {describe(constraint_space)}")
        self.space = constraint_space
        self.start_pose = instance(start_pose, "start_pose", owner, RigidTransform,
                                   what="a RigidTransform (the end-effector frame's pose at the start)")
        self.joint_guess = vector(joint_guess, "joint_guess", owner, unit="rad, m: one per arm joint")
        self.camera = camera
        self.description = text(description, "description", owner)
        if labels is not None and not isinstance(labels, dict):
            raise ArgumentError(f"{owner}: labels must be a dict of plot labels or None, got {describe(labels)}")
        k, m = constraint_space.velocity_size, constraint_space.force_size
        self._labels = labels or {"velocity": [f"r-dot_p[{i}]" for i in range(k)], "velocity_units": "SI",
                                  "force": [f"F[{i}]" for i in range(m)], "force_units": "SI"}

    def base_config(self, options: Dict[str, Any]) -> ScenarioConfig:
        """A ScenarioConfig for this task: velocity-force mode (as every built-in task), constant
        zero desired velocity (k entries) and force (m entries) unless ``default_config`` is given
        ``desired_velocity=[...]``, ``desired_force=[...]``; hydroelastic contact with point-contact
        fallback (an arm's own collision shapes are not hydroelastic)."""
        k, m = self.space.velocity_size, self.space.force_size
        config = ScenarioConfig(
            task=self.name, mode="velocity-force", duration=2.0, gains=HybridGains(),
            desired_velocity=Profile(kind="constant", value=[0.0] * k),
            desired_force=Profile(kind="constant", value=[0.0] * m),
            start=StartConfig(configuration=list(self.start_pose.translation())
                              + list(RollPitchYaw(self.start_pose.rotation()).vector()), in_contact=True))
        config.plant.contact_model = "hydroelastic_with_fallback"
        return config

    def labels(self, config: Optional[ScenarioConfig] = None) -> Dict[str, Any]:
        return self._labels

    # -- the Task protocol (scenario.task) -----------------------------------------------------
    def add_robot(self, plant: MultibodyPlant, config: ScenarioConfig) -> RobotModel:
        robot = self._add_robot(plant)
        if not isinstance(robot, RobotModel):
            raise TypeError(f"task '{self.name}': add_robot must return a RobotModel (see mount_tool), "
                            f"got {type(robot).__name__}")
        return robot

    def add_workpiece(self, plant: MultibodyPlant, config: ScenarioConfig) -> List[GeometryId]:
        return list(self._add_workpiece(plant))

    def constraint_space(self, config: ScenarioConfig) -> ConstraintSpace:
        return self.space

    def start_pose_of(self, config: ScenarioConfig) -> RigidTransform:
        values = list(config.start.configuration)
        if len(values) != 6:
            raise ConfigError(f"task '{self.name}': start.configuration must be [x, y, z, roll, pitch, yaw] "
                              f"of the end-effector frame, got {values}")
        rpy: Array = np.array(values[3:], dtype=float)     # Array: what pydrake's stubs take (core.hints.Array)
        p_WE: Array = np.array(values[:3], dtype=float)
        return RigidTransform(RollPitchYaw(rpy), p_WE)

    def _position_gradient(self, X_WE):
        """(C(x), E_f, grad_p C: rows of C-dot for a unit world velocity of the point along x, y, z)."""
        space, chart = self.space, self.space.chart
        x = chart.configuration(X_WE.rotation().matrix(), X_WE.translation())
        E_f = space.constraint.force_projection(x)
        gradient = np.column_stack([E_f @ chart.task_velocity(x, np.r_[0, 0, 0, axis]) for axis in np.eye(3)])
        return np.atleast_1d(space.constraint.value(x)), gradient

    def pressing_direction(self, config: ScenarioConfig, X_WE: RigidTransform) -> Array:
        """Unit world direction in which the robot pushes the workpiece at the start:
        -sum_i F_d,i grad_p C_i (F_d: force on the robot, in E_f's coordinates)."""
        gradient = self._position_gradient(X_WE)[1]
        desired = np.asarray(config.desired_force.evaluate(0.0)[0], dtype=float)
        direction = -(desired @ gradient)
        norm = np.linalg.norm(direction)
        if not norm > 0:
            raise ConfigError(f"task '{self.name}': the desired force F_d(0) = {desired.tolist()} pushes along no "
                              "position direction of C; set a nonzero desired force on a position row")
        return direction / norm

    def start_field(self) -> Tuple[str, str]:
        """(where, field): what a start's error names: the task and its ``start_pose`` argument (a task file:
        the file and its field)."""
        return f"task '{self.name}'", "start_pose"

    def check_start_pose(self, config: ScenarioConfig, X_WP: RigidTransform, direction: Array) -> None:
        """OffConstraintError if the start pose's controlled point (X_WP) is not on C = 0 within
        ``start.tolerance``, naming the gap or penetration along the pressing direction."""
        value, gradient = self._position_gradient(X_WP)
        rows = [i for i in range(len(value)) if i not in self.space.constraint.kinematic_rows]
        residual = float(np.max(np.abs(value[rows]))) if rows else 0.0
        if residual <= config.start.tolerance:
            return
        # C(p + s d) ~ C + (grad_p C d) s = 0: the distance s along the pressing direction d to the surface.
        slope = gradient[rows] @ direction
        distance = -float(slope @ value[rows]) / float(slope @ slope) if slope @ slope > 0 else float("nan")
        where = (f"a gap: the surface is {distance * 1000:.1f} mm further along the pressing direction"
                 if distance > 0 else
                 f"a penetration: the pad centre is {-distance * 1000:.1f} mm beyond the surface along the pressing "
                 "direction")
        owner, field = self.start_field()
        raise OffConstraintError(
            f"{owner}: {field} is off the constraint, |C| = {residual:.4g} > start.tolerance = "
            f"{config.start.tolerance:g} ({where} {np.round(direction, 3).tolist()}); give a {field} with the "
            "controlled point on C = 0, or set start.in_contact: false to approach from a gap")

    def start_positions(self, scenario: Scenario) -> Array:
        config = scenario.config
        X_WE = self.start_pose_of(config)
        kinematics = scenario.controller.kinematics
        plant = kinematics.plant
        context = plant.CreateDefaultContext()
        X_EP = RigidTransform(kinematics.point_in_frame)
        direction = self.pressing_direction(config, X_WE.multiply(X_EP))
        if config.start.in_contact:
            self.check_start_pose(config, X_WE.multiply(X_EP), direction)

        def positions_at_depth(depth):
            X_target = RigidTransform(X_WE.rotation(), X_WE.multiply(X_EP).translation() + depth * direction)
            return inverse_kinematics(kinematics, context, X_target, self.joint_guess)

        if not config.start.in_contact:
            return positions_at_depth(-config.start.gap)
        return pressing_positions(scenario, positions_at_depth)
