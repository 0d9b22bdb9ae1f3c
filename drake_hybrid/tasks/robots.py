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

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import Solve
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.core.arguments import function, joint_vector, number, positive
from drake_hybrid.core.errors import ConfigError, UnreachablePoseError
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.tasks.arm_chain import fix_arm
from drake_hybrid.tasks.model_files import model_effort_limits, prepare_model

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

    def __init__(self, report, flange, tool_frame, base_pose, tool_axis, effort_limits, name):
        self.report = report
        self.flange = flange
        self.tool_frame = tool_frame
        self.base_pose = base_pose
        self.tool_axis = tool_axis
        self.effort_limits = effort_limits
        self.name = name
        self._plant = None

    def add_robot(self, plant, report=None):
        """Parse the arm into ``plant`` (before Finalize), fix it and attach the pad tool; returns the
        RobotModel that ``CustomTask``'s ``add_robot`` returns."""
        parser = Parser(plant)
        parser.SetAutoRenaming(True)
        arm = parser.AddModels(self.report.model)[0]
        flange, tool = fix_arm(plant, arm, self.flange, self.tool_frame, self.base_pose, self.effort_limits, report)
        return mount_tool(plant, arm, tool, RigidTransform(TOOL_AXES[self.tool_axis], np.zeros(3)))

    @property
    def plant(self):
        """A finalized continuous plant of the arm and pad (no SceneGraph), built once."""
        if self._plant is None:
            plant = MultibodyPlant(0.0)
            self.robot = self.add_robot(plant)
            plant.Finalize()
            self._plant = plant
        return self._plant

    @property
    def num_joints(self):
        return self.plant.num_positions()

    def joint_limits(self):
        """(lower, upper) position limits of the arm's joints (rad; +-inf for continuous joints)."""
        return self.plant.GetPositionLowerLimits(), self.plant.GetPositionUpperLimits()

    def pad_jacobian(self, q):
        """The 6 x n spatial Jacobian (angular; translational, world frame) of the pad centre at ``q``
        (ArgumentError unless a vector of the arm's number of finite positions)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, joint_vector(q, "q", "LoadedArm.pad_jacobian", plant))
        frame = plant.GetFrameByName(self.robot.end_effector_frame)
        return plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, np.zeros(3),
                                                 plant.world_frame(), plant.world_frame())

    def condition_number(self, q, length_scale=None):
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
            base = self.base_pose.translation() if self.base_pose is not None else np.zeros(3)
            length_scale = max(float(np.linalg.norm(self.pad_pose(q).translation() - base)), 0.1)
        singular = np.linalg.svd(np.vstack([J[:3], J[3:] / length_scale]), compute_uv=False)
        return float(singular[0] / singular[-1]) if singular[-1] > 0 else float("inf")

    def pad_pose(self, q):
        """X_WE of the pad centre frame at joint positions ``q`` (ArgumentError unless a vector of the
        arm's number of finite positions)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, joint_vector(q, "q", "LoadedArm.pad_pose", plant))
        return plant.GetFrameByName(self.robot.end_effector_frame).CalcPoseInWorld(context)

    def workpiece_penetrations(self, add_workpiece, q):
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

    def find_joint_guess(self, X_WE, seeds=12, rng=0, near=None, add_workpiece=None, position_tolerance=1e-6,
                         angle_tolerance=1e-6, limit_margin=0.05):
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
        low = np.where(np.isfinite(lower), lower, -np.pi) + limit_margin
        high = np.where(np.isfinite(upper), upper, np.pi) - limit_margin
        generator = np.random.default_rng(rng)
        if near is not None:
            near = joint_vector(near, "near", "LoadedArm.find_joint_guess", self.plant, unit="rad, m: one per arm joint")
        seeds = number(seeds, "seeds", "LoadedArm.find_joint_guess", low=1, integer=True)
        starts = ([np.clip(near, low, high)] if near is not None else []) + [(low + high) / 2]
        starts += [generator.uniform(low, high) for _ in range(max(seeds - len(starts), 0))]
        frame = plant.GetFrameByName(self.robot.end_effector_frame)
        best, solutions = None, 0
        for start in starts:
            ik = InverseKinematics(plant, with_joint_limits=False)
            q = ik.q()
            ik.prog().AddBoundingBoxConstraint(low, high, q)
            p = X_WE.translation()
            ik.AddPositionConstraint(frame, np.zeros(3), plant.world_frame(), p - position_tolerance,
                                     p + position_tolerance)
            ik.AddOrientationConstraint(plant.world_frame(), X_WE.rotation(), frame, RotationMatrix(),
                                        angle_tolerance)
            ik.prog().AddQuadraticErrorCost(1e-3 * np.eye(len(start)), start, q)
            # SNOPT often reports "infeasible" at a solution within 1e-6 of the pose: judge by the pose itself.
            solution = Solve(ik.prog(), start).GetSolution(q)
            if np.any(solution < low - 1e-9) or np.any(solution > high + 1e-9):
                continue
            X = self.pad_pose(solution)
            error = max(np.linalg.norm(X.translation() - X_WE.translation()),
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


def load_arm(path, flange, tool_frame=None, base_pose=None, tool_axis="+z", collision="convert", packages=None,
             cache_dir=None):
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
