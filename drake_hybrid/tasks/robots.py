"""Any arm from a URDF or SDF model package, ready for the hybrid law in one call.

``load_arm(path, flange=...)`` turns a model file as model packages ship it into one that Drake
parses and the law can use, and says what it changed (``tasks.model_files.LoadReport``)::

    arm = load_arm(share / "robots/ur_description/urdf/ur10_robot.urdf", flange="tool0")
    print(arm.report)                            # every change, one line each
    guess = arm.find_joint_guess(X_WE_start)     # inverse kinematics from several seeds
    task = CustomTask("ur10-plane", add_robot=arm.add_robot, ..., joint_guess=guess.positions)

It fixes the file once (``tasks.model_files.prepare_model``: meshes converted, URIs made absolute,
materials renamed; cached by content hash) and the plant every time ``add_robot(plant)`` parses it
(the simulation plant and the controller's plant; ``tasks.arm_chain.fix_arm``: base welded at
``base_pose``, joints off the base-to-flange chain welded, actuators with the file's effort limits),
then welds the pad tool (``models/pad_tool.sdf``) at ``tool_frame`` (default: the flange), its
approach axis along the tool frame's ``tool_axis``.

Unknown frames raise ``UnknownFrameError`` listing the model's frames. The joint-guess finder
(``LoadedArm.find_joint_guess``) runs Drake's ``InverseKinematics`` from several seeds within the
joint limits and keeps the solution whose pad Jacobian is best conditioned.
"""

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, List, Mapping, Optional, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike

from pydrake.geometry import GeometryId
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import Solve
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.core.arguments import function, joint_vector, number, positive
from drake_hybrid.core.errors import ConfigError, UnreachablePoseError
from drake_hybrid.core.hints import Array
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.station.tools import ToolConfig
from drake_hybrid.tasks.arm_chain import fix_arm
from drake_hybrid.tasks.model_files import LoadReport, model_effort_limits, prepare_model

TOOL_AXES = {"+z": RotationMatrix(), "-z": RotationMatrix.MakeXRotation(np.pi),
             "+x": RotationMatrix.MakeYRotation(np.pi / 2), "-x": RotationMatrix.MakeYRotation(-np.pi / 2),
             "+y": RotationMatrix.MakeXRotation(-np.pi / 2), "-y": RotationMatrix.MakeXRotation(np.pi / 2)}


@dataclass
class JointGuess:
    """The result of ``LoadedArm.find_joint_guess``."""

    positions: np.ndarray                          # the chosen joint positions
    condition_number: float                        # LoadedArm.condition_number there (translation scaled)
    seeds: int                                     # inverse-kinematics problems solved
    solutions: int                                 # of them, how many reached the pose (within the limits, clear)
    limit_margin: float                            # smallest distance to a joint limit (rad or m)


class LoadedArm:
    """An arm made usable by ``load_arm``: ``add_robot(plant)`` for ``CustomTask``, the ``report``,
    the joint limits and ``find_joint_guess``."""

    def __init__(self, report: LoadReport, flange: str, tool_frame: str, base_pose: Optional[RigidTransform],
                 tool_axis: str, effort_limits: Mapping[str, float], name: str) -> None:
        self.report = report
        self.flange = flange
        self.tool_frame = tool_frame
        self.base_pose = base_pose
        self.tool_axis = tool_axis
        self.effort_limits = effort_limits
        self.name = name
        self._plant: Optional[MultibodyPlant] = None

    def add_robot(self, plant: MultibodyPlant, report: Optional[LoadReport] = None,
                  tool: Optional[ToolConfig] = None) -> RobotModel:
        """Parse the arm into ``plant`` (before Finalize), fix it and attach the pad tool (the ball, or
        ``tool``: a ``station.tools.ToolConfig``); returns the RobotModel that ``CustomTask``'s ``add_robot``
        returns."""
        parser = Parser(plant)
        parser.SetAutoRenaming(True)
        arm = parser.AddModels(Path(self.report.model))[0]
        flange, tool_frame = fix_arm(plant, arm, self.flange, self.tool_frame, self.base_pose, self.effort_limits,
                                     report)
        origin: Array = np.zeros(3)
        return mount_tool(plant, arm, tool_frame, RigidTransform(TOOL_AXES[self.tool_axis], origin), tool=tool)

    @property
    def plant(self) -> MultibodyPlant:
        """A finalized continuous plant of the arm and pad (no SceneGraph), built once."""
        if self._plant is None:
            plant = MultibodyPlant(0.0)
            self.robot = self.add_robot(plant)
            plant.Finalize()
            self._plant = plant
        return self._plant

    @property
    def num_joints(self) -> int:
        return self.plant.num_positions()

    def joint_limits(self) -> Tuple[Array, Array]:
        """(lower, upper) position limits of the arm's joints (rad; +-inf for continuous joints)."""
        return self.plant.GetPositionLowerLimits(), self.plant.GetPositionUpperLimits()

    def pad_jacobian(self, q: ArrayLike) -> Array:
        """The 6 x n spatial Jacobian (angular; translational, world frame) of the pad centre at ``q``
        (ArgumentError unless a vector of the arm's number of finite positions)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, joint_vector(q, "q", "LoadedArm.pad_jacobian", plant))
        frame = plant.GetFrameByName(self.robot.end_effector_frame)
        origin: Array = np.zeros(3)
        return plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, origin,
                                                 plant.world_frame(), plant.world_frame())

    def condition_number(self, q: ArrayLike, length_scale: Optional[float] = None) -> float:
        """cond(S J) of the pad's spatial Jacobian at ``q``, its translational rows divided by
        ``length_scale`` (m; default: the distance from the base to the pad, at least 0.1 m) so that
        the number does not depend on the unit of length. ArgumentError for a ``q`` that is not a
        vector of the arm's number of finite positions or a ``length_scale`` that is not a positive
        finite number or None."""
        q = joint_vector(q, "q", "LoadedArm.condition_number", self.plant)
        length_scale = positive(length_scale, "length_scale", "LoadedArm.condition_number", unit="m",
                                allow_none=True)
        J = self.pad_jacobian(q)
        if length_scale is None:
            base: Array = self.base_pose.translation() if self.base_pose is not None else np.zeros(3)
            length_scale = max(float(np.linalg.norm(self.pad_pose(q).translation() - base)), 0.1)
        singular = np.linalg.svd(np.vstack([J[:3], J[3:] / length_scale]), compute_uv=False)
        return float(singular[0] / singular[-1]) if singular[-1] > 0 else float("inf")

    def pad_pose(self, q: ArrayLike) -> RigidTransform:
        """X_WE of the pad centre frame at joint positions ``q`` (ArgumentError unless a vector of the
        arm's number of finite positions)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, joint_vector(q, "q", "LoadedArm.pad_pose", plant))
        return plant.GetFrameByName(self.robot.end_effector_frame).CalcPoseInWorld(context)

    def workpiece_penetrations(self, add_workpiece: Callable[[MultibodyPlant], Iterable[GeometryId]],
                               q: ArrayLike) -> List[str]:
        """Names of the arm's bodies (the pad excepted) whose collision shapes penetrate the
        workpiece of ``add_workpiece(plant) -> geometry ids`` (CustomTask's) at joint positions ``q``
        (ArgumentError unless a vector of the arm's number of finite positions)."""
        owner = "LoadedArm.workpiece_penetrations"
        function(add_workpiece, "add_workpiece", owner, "add_workpiece(plant) -> geometry ids")
        q = joint_vector(q, "q", owner, self.plant)
        if getattr(self, "_clearance_probe", (None,))[0] is not add_workpiece:
            builder = DiagramBuilder()
            plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
            robot = self.add_robot(plant)
            workpiece = set(add_workpiece(plant))
            plant.Finalize()
            diagram = builder.Build()
            self._clearance_probe = (add_workpiece, diagram, plant, scene_graph, robot, workpiece)
        _, diagram, plant, scene_graph, robot, workpiece = self._clearance_probe
        context = diagram.CreateDefaultContext()
        plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.arm, q)
        query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
        inspector = query.inspector()
        pad = set(robot.pad_geometries)
        touching = set()
        for pair in query.ComputePointPairPenetration():
            ids = {pair.id_A, pair.id_B}
            if ids & workpiece and not ids & pad and not ids <= workpiece:
                (other,) = ids - workpiece
                touching.add(plant.GetBodyFromFrameId(inspector.GetFrameId(other)).name())
        return sorted(touching)

    def find_joint_guess(self, X_WE: RigidTransform, seeds: int = 12, rng: Union[int, np.random.Generator] = 0,
                         near: Optional[ArrayLike] = None,
                         add_workpiece: Optional[Callable[[MultibodyPlant], Iterable[GeometryId]]] = None,
                         position_tolerance: float = 1e-6, angle_tolerance: float = 1e-6,
                         limit_margin: float = 0.05) -> JointGuess:
        """Joint positions that put the pad centre frame at ``X_WE`` (a RigidTransform: e.g. the
        start pose of a CustomTask, its point on the surface), from Drake's InverseKinematics.

        Solves from ``seeds`` starts: ``near`` (if given), the middle of the joint limits, and
        uniform random positions within the limits (continuous joints within +-pi; ``rng`` a seed
        or numpy Generator), each held ``limit_margin`` inside the limits. With ``add_workpiece``
        (CustomTask's), solutions where an arm link (not the pad) penetrates the workpiece are
        rejected. Of the solutions left, the one whose pad Jacobian is best conditioned
        (``condition_number``: translation rows scaled by the base-to-pad distance) is returned
        (a JointGuess). UnreachablePoseError if none is left."""
        plant = self.plant
        lower, upper = self.joint_limits()
        low: Array = np.where(np.isfinite(lower), lower, -np.pi) + limit_margin
        high: Array = np.where(np.isfinite(upper), upper, np.pi) - limit_margin
        generator = np.random.default_rng(rng)
        if near is not None:
            near = joint_vector(near, "near", "LoadedArm.find_joint_guess", self.plant, unit="rad, m: one per arm joint")
        seeds = number(seeds, "seeds", "LoadedArm.find_joint_guess", low=1, integer=True)
        starts: List[Array] = ([np.clip(near, low, high)] if near is not None else []) + [(low + high) / 2]
        starts += [generator.uniform(low, high) for _ in range(max(seeds - len(starts), 0))]
        frame = plant.GetFrameByName(self.robot.end_effector_frame)
        best, solutions = None, 0
        for start in starts:
            ik = InverseKinematics(plant, with_joint_limits=False)
            q = ik.q()
            ik.prog().AddBoundingBoxConstraint(low, high, q)
            p: Array = X_WE.translation()
            origin: Array = np.zeros(3)
            lower_p: Array = p - position_tolerance
            upper_p: Array = p + position_tolerance
            ik.AddPositionConstraint(frame, origin, plant.world_frame(), lower_p, upper_p)
            ik.AddOrientationConstraint(plant.world_frame(), X_WE.rotation(), frame, RotationMatrix(),
                                        angle_tolerance)
            weights: Array = 1e-3 * np.eye(len(start))
            ik.prog().AddQuadraticErrorCost(weights, start, q)
            # SNOPT often reports "infeasible" at a solution within 1e-6 of the pose: judge by the pose itself.
            solution: Array = Solve(ik.prog(), start).GetSolution(q)
            if np.any(solution < low - 1e-9) or np.any(solution > high + 1e-9):
                continue
            X = self.pad_pose(solution)
            p_WE: Array = X.translation()
            error = max(np.linalg.norm(p_WE - X_WE.translation()),
                        X.rotation().inverse().multiply(X_WE.rotation()).ToAngleAxis().angle())
            if error > 10 * max(position_tolerance, angle_tolerance):
                continue
            if add_workpiece is not None and self.workpiece_penetrations(add_workpiece, solution):
                continue
            solutions += 1
            condition = self.condition_number(solution)
            if best is None or condition < best[1]:
                best = (solution, condition)
        if best is None:
            raise UnreachablePoseError(
                f"arm '{self.name}': no joint positions within the limits put the pad centre at "
                f"p = {np.round(X_WE.translation(), 4).tolist()} m with the requested orientation"
                f"{' clear of the workpiece' if add_workpiece is not None else ''} ({len(starts)} inverse-kinematics "
                "seeds); move the workpiece or the base (base_pose), change the tool axis, or try more seeds")
        margin = float(np.min(np.minimum(best[0] - lower, upper - best[0])))
        return JointGuess(positions=best[0], condition_number=best[1], seeds=len(starts), solutions=solutions,
                          limit_margin=margin)


def load_arm(path: Union[str, os.PathLike], flange: str, tool_frame: Optional[str] = None,
             base_pose: Optional[RigidTransform] = None, tool_axis: str = "+z", collision: str = "convert",
             packages: Optional[Mapping[str, Union[str, Path]]] = None,
             cache_dir: Union[str, os.PathLike, None] = None) -> LoadedArm:
    """Make the arm of URDF/SDF ``path`` usable by the hybrid law (see the module docstring).

    Args:
        path: the model file (``package://`` mesh URIs are resolved from the package.xml files above
            it and ``packages``).
        flange: the frame (link) that ends the actuated chain; joints beyond it are welded.
        tool_frame: the frame the pad tool is welded to, its approach axis along ``tool_axis``
            (default: ``flange``); it must be carried by the flange (e.g. a TCP frame on the hand).
        base_pose: X_W_base, where the arm's base is welded to the world (default: identity).
        tool_axis: the tool frame's axis the pad points along: one of +z, -z, +x, -x, +y, -y.
        collision: "convert" (STL/DAE collision meshes to OBJ) or "drop" (remove them).
        packages: {package name: folder} for ``package://`` URIs not found by package.xml.
        cache_dir: where converted files go (default: ``default_cache_dir()``).

    Returns a LoadedArm; its ``report`` lists every change.
    """
    if tool_axis not in TOOL_AXES:
        raise ConfigError(f"load_arm: tool_axis must be one of {', '.join(TOOL_AXES)}, got {tool_axis!r}")
    report = prepare_model(path, collision=collision, packages=packages, cache_dir=cache_dir)
    tool_frame = tool_frame or flange
    report.flange, report.tool_frame = flange, tool_frame
    name = Path(path).stem
    arm = LoadedArm(report, flange, tool_frame, base_pose, tool_axis, model_effort_limits(path), name)
    # Parse once into a plant without SceneGraph to check the frames and record the plant-level changes.
    plant = MultibodyPlant(0.0)
    arm.robot = arm.add_robot(plant, report)
    plant.Finalize()
    arm._plant = plant
    report.changes.append(f"pad tool welded at '{tool_frame}' along its {tool_axis} axis; the controlled point is "
                          "its centre (frame 'pad_center')")
    return arm
