"""A contact start in your own diagram: the arm at rest pressing with F_d, every state around it set.

``solve_contact_start`` takes the systems of ``station.loop.add_hybrid_controller`` in your
diagram's context: inverse kinematics to your start pose, the depth where the contact's rest force
equals F_d (``rest_contact_wrench``: the pressure of SceneGraph's hydroelastic contact surfaces,
integrated), the typed checks (on the constraint, the branch, a pushing force, the workpiece where C
says, the links clear of the scene), then ``station.start.prime_start``.
"""

from typing import Iterable, Optional, cast

import numpy as np
from numpy.typing import ArrayLike

from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import GeometryId, HydroelasticContactRepresentation, QueryObject
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.core.arguments import describe, instance, joint_vector, positive, vector
from drake_hybrid.core.errors import ArgumentError, ConfigError, OffConstraintError, UnreachablePoseError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.kinematics import inverse_kinematics
from drake_hybrid.core.preconditions import check_pushing_force
from drake_hybrid.station.clearance import check_robot_clearance
from drake_hybrid.station.contact import geometry_ids
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.root_context import check_root_context
from drake_hybrid.station.start import holding_torque, pressing_depth, prime_start
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor


def rest_contact_wrench(plant: MultibodyPlant, plant_context: Context, robot_geometries: Iterable[GeometryId],
                        p_WP: ArrayLike) -> np.ndarray:
    """The wrench on the robot at rest from its hydroelastic contacts, at the point ``p_WP`` (world),
    as a Drake SpatialForce vector [torque; force] (N m, N): the pressure of every contact surface
    touching ``robot_geometries`` integrated over its faces (a rest state has no dissipation and no
    friction). A static reading of any plant, discrete or continuous, sampled output ports or not,
    from its SceneGraph's query in ``plant_context``.

    ArgumentError for a ``plant`` that is not a MultibodyPlant connected to a SceneGraph, a
    ``plant_context`` that is not the plant's, ``robot_geometries`` that is not a non-empty collection of
    GeometryIds registered in that SceneGraph (e.g. ``RobotModel.pad_geometries``), a ``p_WP`` that is not
    3 finite numbers (m)."""
    owner = "rest_contact_wrench"
    if not hasattr(plant, "get_geometry_query_input_port") or not hasattr(plant, "is_finalized"):
        raise ArgumentError(f"{owner}: plant must be a MultibodyPlant, got {describe(plant)}")
    p_WP = vector(p_WP, "p_WP", owner, 3, unit="m, world")
    try:
        plant.ValidateContext(plant_context)
    except (RuntimeError, TypeError):
        raise ArgumentError(f"{owner}: plant_context must be the plant's own context (plant.GetMyContextFromRoot("
                            f"root_context)), got {describe(plant_context)} of another system") from None
    port = plant.get_geometry_query_input_port()
    if not port.HasValue(plant_context):
        raise ArgumentError(f"{owner}: plant's geometry_query input is not connected: the plant must be registered "
                            "with a SceneGraph (AddMultibodyPlant) in a built diagram")
    query = cast(QueryObject, port.Eval(plant_context))        # pydrake's stubs: an object
    robot = _registered_geometries(robot_geometries, query.inspector(), owner)
    wrench = np.zeros(6)
    try:
        surfaces = query.ComputeContactSurfaces(HydroelasticContactRepresentation.kTriangle)
    except RuntimeError as error:        # a touching pair without a hydroelastic representation
        raise ConfigError(f"rest_contact_wrench: {str(error).splitlines()[0]} -- the start is solved on "
                          "hydroelastic contact: give the workpiece a rigid hydroelastic geometry "
                          "(station.workpieces.add_rigid_workpiece) and let only the tool touch it "
                          "(only_tool_touches)") from None
    for surface in surfaces:
        if surface.id_M() in robot:
            sign = 1.0                 # the faces' normals point out of N into M: the force on M
        elif surface.id_N() in robot:
            sign = -1.0
        else:
            continue
        mesh, pressure = surface.tri_mesh_W(), surface.tri_e_MN()
        for face in range(mesh.num_triangles()):
            normal: Array = mesh.face_normal(face)
            force = sign * float(pressure.Evaluate(face, CENTROID)) * mesh.area(face) * normal
            wrench[:3] += np.cross(mesh.element_centroid(face) - p_WP, force)
            wrench[3:] += force
    return wrench


def _registered_geometries(robot_geometries, inspector, owner):
    """``robot_geometries`` as a set of GeometryIds, each registered with the SceneGraph of ``inspector``."""
    allowed = "a non-empty collection of GeometryIds of the plant's SceneGraph (e.g. RobotModel.pad_geometries)"
    robot_geometries = geometry_ids(robot_geometries, "robot_geometries", owner, allowed,
                                    collections=(list, tuple, set, frozenset), nonempty=True)
    known = set(inspector.GetAllGeometryIds())
    unknown = [entry for entry in robot_geometries if entry not in known]
    if unknown:
        raise ArgumentError(f"{owner}: robot_geometries holds {len(unknown)} GeometryId(s) not registered in the "
                            f"plant's SceneGraph (another SceneGraph's?), e.g. {unknown[0]}: it must be {allowed}")
    return set(robot_geometries)


CENTROID: Array = np.full(3, 1.0 / 3.0)           # a triangle's centroid in barycentric coordinates


def check_start_sensor(systems: HybridSystems, owner: str) -> None:
    """ArgumentError for a ``WristForceTorqueSensor`` on a continuous plant: its reading is the weld's
    reaction, which on a continuous plant depends on the accelerations the controller's torque causes
    (and leaves out the tool's weight with strict hydroelastic contact), so neither the reading nor
    a fixed point of priming the filter with it is the contact's rest wrench (measured on a Kinova Jaco
    pressing 10 N: the filter primed to 11.94 N, the sensor then reading 11.46 N; iterated, the prime
    settles at 11.54 N with max |x-dot| still 12.3; with hydroelastic_with_fallback max |x-dot| 565)."""
    plant = cast(MultibodyPlant, systems.plant)        # a simulated station's (a real arm's has none)
    if isinstance(systems.sensor, WristForceTorqueSensor) and not plant.time_step() > 0:
        raise ArgumentError(
            f"{owner}: systems has a WristForceTorqueSensor on a continuous plant (time_step = 0): its reading (the "
            "weld's reaction) depends on the accelerations the controller's torque causes, so the start cannot be "
            "put at rest; use the contact sensor (sensor=None) for the continuous loop, or a discrete plant")


def solve_contact_start(diagram: Diagram, root_context: Context, systems: HybridSystems, start_pose: RigidTransform,
                        joint_guess: ArrayLike, desired_force: Optional[ArrayLike] = None, max_depth: float = 0.01,
                        tolerance: float = 1e-3) -> np.ndarray:
    """Put your diagram at a start pressing with F_d, at rest, and set every state around the plant.

    ``systems`` is what ``station.loop.add_hybrid_controller`` returned; ``start_pose`` the
    end-effector frame E's pose (RigidTransform, world) with its point P on the surface C = 0;
    ``joint_guess`` the arm's joint positions near it (the inverse kinematics' seed). The pad is
    pushed into the workpiece along -sum_i F_d,i grad_p C_i (``desired_force``, m entries in E_f's
    coordinates; default the command source's at t = 0: a surface's inward normal), turned at each
    depth about its point as the constraint's held (kinematic) rows want it, to the depth where the
    contact's rest force in E_f's coordinates equals F_d (Brent's method on ``rest_contact_wrench``);
    then ``prime_start`` with the torque that holds it there. Returns the arm's joint positions. (A
    start ``gap`` above the surface for a guarded approach is ``solve_approach_start``.)

    Typed errors before the first step: a start pose off C = 0 beyond ``tolerance`` (C's units) or
    on the wrong branch (OffConstraintError, BranchError), E singular there (ConstraintRankError,
    ChartSingularityError), a pulling F_d (ForceSignError), a workpiece that is not where C says
    (OffConstraintError), a link of the arm through the workpiece or the scene (StartCollisionError,
    ``robot_penetrations``), the inverse kinematics failing (UnreachablePoseError naming start_pose and
    joint_guess), a desired force the contact cannot give within ``max_depth`` (ArgumentError), a
    ``diagram``, ``root_context`` and ``systems`` that do not belong together (ArgumentError,
    ``station.root_context``), and a wrist force/torque sensor on a continuous plant (ArgumentError:
    no primed reading makes that start a rest, see ``systems.wrist_force_torque_sensor.WristForceTorqueSensor``).
    """
    owner = "solve_contact_start"
    check_root_context(diagram, root_context, systems, owner)
    instance(start_pose, "start_pose", owner, RigidTransform)
    max_depth = positive(max_depth, "max_depth", owner, unit="m")
    space, kinematics, joint_guess, tolerance = _checked_start_pose(systems, start_pose, joint_guess, tolerance,
                                                                    owner)
    desired = _desired_force(systems, root_context, desired_force, owner)
    direction = _pressing_direction(space, start_pose, desired) if np.linalg.norm(desired) > 0 else np.zeros(3)

    def pose_at_depth(depth):
        return _held_pose(space, RigidTransform(start_pose.rotation(), start_pose.translation() + depth * direction))

    return _press_and_prime(diagram, root_context, systems, pose_at_depth, joint_guess, desired, max_depth,
                            tolerance, owner, "start_pose")


def solve_path_start(diagram: Diagram, root_context: Context, systems: HybridSystems, joint_guess: ArrayLike,
                     gap: float = 0.005, max_depth: float = 0.01, tolerance: float = 1e-3) -> np.ndarray:
    """Put your diagram at the start of its path job (``add_hybrid_controller(..., path=job)``), at rest,
    and set every state around the plant. Returns the arm's joint positions.

    With a contact supervisor that starts in APPROACH or TARE (``initial_phase``), the pad centre is put
    ``gap`` (m) above the path's first point along the surface's normal, turned as the constraint's
    held rows want it (``PathJob.pose_at_depth``), holding only gravity: the guarded approach lands
    it. Otherwise it presses there with the path's first force, pushed along the normal to the depth
    where the contact's rest force equals it (as ``solve_contact_start``). ``joint_guess``: the arm's
    joint positions near the start (the inverse kinematics' seed). The typed errors are
    ``solve_contact_start``'s; ArgumentError for ``systems`` without a path job."""
    owner = "solve_path_start"
    check_root_context(diagram, root_context, systems, owner)
    job = systems.path
    if job is None:
        raise ArgumentError(f"{owner}: systems has no path job: build it with add_hybrid_controller(..., "
                            "path=path_job(surface, offset, settings)), or start with solve_contact_start")
    check_start_sensor(systems, owner)
    kinematics = systems.controller.kinematics
    joint_guess = joint_vector(joint_guess, "joint_guess", owner, kinematics.plant)
    gap = positive(gap, "gap", owner, unit="m")
    max_depth = positive(max_depth, "max_depth", owner, unit="m")
    tolerance = positive(tolerance, "tolerance", owner)
    desired = _desired_force(systems, root_context, None, owner)
    supervisor = systems.supervisor
    if supervisor is None or supervisor.initial_phase == ContactPhase.CONTACT:
        return _press_and_prime(diagram, root_context, systems, job.pose_at_depth, joint_guess, desired, max_depth,
                                tolerance, owner, "the path's first point")
    q0 = _positions_at(kinematics, kinematics.plant.CreateDefaultContext(), job.pose_at_depth(-gap), joint_guess,
                       0.0, owner, f"the pose {gap:g} m above the path's first point")
    _rest_at(diagram, root_context, systems, q0, np.zeros_like(desired), owner)
    return q0


def _position_gradient(space, x):
    """grad_p C: C-dot per unit world velocity of the controlled point along x, y, z (m x 3)."""
    E_f = space.constraint.force_projection(x)
    return np.column_stack([E_f @ space.chart.task_velocity(x, np.concatenate([np.zeros(3), axis]))
                            for axis in np.eye(3)])


def _pressing_direction(space, X_WP, desired):
    """The unit world direction the pad pushes the workpiece at rest pressing with ``desired``: -sum_i F_d,i
    grad_p C_i (the force part of the wrench E_f^T F_d the rows read as F_d, reversed): a surface's inward
    normal for the signed distances of ``core.surfaces``."""
    x = space.chart.configuration(X_WP.rotation().matrix(), X_WP.translation())
    direction = -(np.asarray(desired, dtype=float) @ _position_gradient(space, x))
    norm = float(np.linalg.norm(direction))
    return direction / norm if norm > 0 else direction


# The held rows' residual a start's orientation is turned to (C's units: a sine) and the Newton steps allowed.
HELD_ROWS_TOLERANCE, HELD_ROWS_STEPS = 1e-12, 20


def _held_pose(space, X_WP):
    """``X_WP`` turned about its point until the constraint's kinematic rows (held by the controller, e.g. the
    approach vector along a surface's normal) are zero there (Newton's method on the rotation; as it was if
    the constraint has none, or they do not depend on the orientation)."""
    kinematic = list(space.constraint.kinematic_rows)
    if not kinematic:
        return X_WP
    chart, p, R = space.chart, X_WP.translation(), X_WP.rotation()
    for _ in range(HELD_ROWS_STEPS):
        x = chart.configuration(R.matrix(), p)
        residual = np.atleast_1d(space.constraint.value(x))[kinematic]
        if not np.max(np.abs(residual)) > HELD_ROWS_TOLERANCE:
            break
        E_f = space.constraint.force_projection(x)[kinematic]
        turning = np.column_stack([E_f @ chart.task_velocity(x, np.concatenate([axis, np.zeros(3)]))
                                   for axis in np.eye(3)])
        omega = -np.linalg.lstsq(turning, residual, rcond=None)[0]
        angle = float(np.linalg.norm(omega))
        if not angle > 0:
            break
        R = RotationMatrix(AngleAxis(angle, omega / angle)).multiply(R)
    return RigidTransform(R, p)


def solve_approach_start(diagram: Diagram, root_context: Context, systems: HybridSystems, start_pose: RigidTransform,
                         joint_guess: ArrayLike, gap: float = 0.005, tolerance: float = 1e-3) -> np.ndarray:
    """Put your diagram at rest with the pad ``gap`` (m) above ``start_pose`` for the contact supervisor's
    guarded approach, and set every state around the plant. Returns the arm's joint positions.

    ``start_pose``: the end-effector frame E's pose (world) with its point P on the surface C = 0, where the
    approach lands; the pad is put ``gap`` back from it against the pressing direction (-sum_i F_d,i
    grad_p C_i, F_d the command source's at t = 0: along a surface's outward normal), turned about its point
    as the constraint's held (kinematic) rows want it there, holding only gravity. ``joint_guess``: the arm's
    joint positions near it (the inverse kinematics' seed). The path job's own is ``solve_path_start``.

    Typed errors before the first step: ``systems`` without a contact supervisor that starts in APPROACH or
    TARE (ArgumentError: ``add_hybrid_controller(..., supervision=SupervisionConfig(),
    initial_phase=ContactPhase.APPROACH)``; without one, a start off the surface is refused), a start pose
    off C = 0 beyond ``tolerance`` or on the wrong branch, a pulling or zero F_d (no direction to approach
    along), a link of the arm through the scene, the inverse kinematics failing (UnreachablePoseError),
    and the argument errors of ``solve_contact_start``."""
    owner = "solve_approach_start"
    check_root_context(diagram, root_context, systems, owner)
    instance(start_pose, "start_pose", owner, RigidTransform)
    supervisor = systems.supervisor
    if supervisor is None or supervisor.initial_phase == ContactPhase.CONTACT:
        raise ArgumentError(f"{owner}: systems has no contact supervisor that starts in APPROACH (or TARE): build it "
                            "with add_hybrid_controller(..., supervision=SupervisionConfig(), "
                            "initial_phase=ContactPhase.APPROACH), or start pressing with solve_contact_start")
    gap = positive(gap, "gap", owner, unit="m")
    space, kinematics, joint_guess, tolerance = _checked_start_pose(systems, start_pose, joint_guess, tolerance,
                                                                    owner)
    desired = _desired_force(systems, root_context, None, owner)
    mask = np.array([0.0 if i in space.constraint.kinematic_rows else 1.0 for i in range(space.force_size)])
    check_pushing_force(desired, force_controlled=mask, where=f"{owner} (the command source's desired_force)")
    if not np.linalg.norm(desired) > 0:
        raise ArgumentError(f"{owner}: the command source's desired force at t = 0 is zero: the approach goes along "
                            "the direction it presses in; command the force the pad should press with")
    direction = _pressing_direction(space, start_pose, desired)
    pose = _held_pose(space, RigidTransform(start_pose.rotation(), start_pose.translation() - gap * direction))
    q0 = _positions_at(kinematics, kinematics.plant.CreateDefaultContext(), pose, joint_guess, 0.0, owner,
                       f"start_pose moved {gap:g} m back from the surface")
    _rest_at(diagram, root_context, systems, q0, np.zeros_like(desired), owner)
    return q0


def _checked_start_pose(systems, start_pose, joint_guess, tolerance, owner):
    """(space, kinematics, joint_guess, tolerance) of a start at ``start_pose``, checked: the sensor, the joint
    guess and the tolerance, the pose reachable (UnreachablePoseError first) and then on C = 0 as given."""
    check_start_sensor(systems, owner)
    space, kinematics = systems.constraint_space, systems.controller.kinematics
    joint_guess = joint_vector(joint_guess, "joint_guess", owner, kinematics.plant)
    tolerance = positive(tolerance, "tolerance", owner)
    _positions_at(kinematics, kinematics.plant.CreateDefaultContext(), start_pose, joint_guess, 0.0, owner,
                  "start_pose")
    _check_start_pose(space, start_pose, tolerance, owner)
    return space, kinematics, joint_guess, tolerance


def _check_start_pose(space, start_pose, tolerance, owner):
    """OffConstraintError (naming ``owner`` and start_pose) for a ``start_pose`` whose point is off C = 0 beyond
    ``tolerance``, or whose orientation is off the held rows by more; BranchError on the wrong branch."""
    x = space.chart.configuration(start_pose.rotation().matrix(), start_pose.translation())
    try:
        space.constraint.check_satisfied(x, tolerance)
    except OffConstraintError as error:
        raise OffConstraintError(f"{owner}: start_pose: {error}") from None
    space.constraint.check_branch(x)


def _desired_force(systems, root_context, desired_force, owner):
    """F_d for the start (m entries, the kinematic rows zeroed): ``desired_force`` or the command source's at t = 0."""
    space = systems.constraint_space
    if desired_force is None:
        if systems.source is None:
            raise ArgumentError(f"{owner}: desired_force is needed when the controller has no command source")
        source_context = systems.source.GetMyContextFromRoot(root_context)
        desired_force = systems.source.GetOutputPort("desired_force").Eval(source_context)
    desired = vector(desired_force, "desired_force", owner, space.force_size)
    mask = np.array([0.0 if i in space.constraint.kinematic_rows else 1.0 for i in range(space.force_size)])
    return desired * mask


def _positions_at(kinematics, controller_context, X_target, joint_guess, depth, owner, what):
    """The inverse kinematics to ``X_target`` from ``joint_guess``; UnreachablePoseError naming ``what``."""
    try:
        return inverse_kinematics(kinematics, controller_context, X_target, joint_guess)
    except (UnreachablePoseError, np.linalg.LinAlgError) as error:     # no convergence, outside the joint limits
        where = what if depth == 0 else f"{what} pushed {depth * 1000:.3g} mm into the workpiece"
        raise UnreachablePoseError(f"{owner}: {where} is not reached from joint_guess: {error} Give a "
                                   f"reachable {what} or a joint_guess nearer to it") from None


def _rest_at(diagram, root_context, systems, q0, desired, owner):
    """The arm at rest at ``q0`` (its links clear of the scene), every state around it primed to hold it
    there pressing with ``desired``."""
    plant, robot = systems.plant, systems.robot
    check_robot_clearance(diagram, root_context, systems, q0, owner)
    plant_context = plant.GetMyMutableContextFromRoot(root_context)
    plant.SetPositions(plant_context, robot.arm, q0)
    plant.SetVelocities(plant_context, robot.arm, np.zeros(len(q0)))
    prime_start(systems, root_context, holding_torque(systems, q0, desired))


def _press_and_prime(diagram, root_context, systems, pose_at_depth, joint_guess, desired, max_depth, tolerance,
                     owner, what):
    """The start pressing with ``desired``: the pose ``pose_at_depth(0)`` checked on C = 0, the depth where
    the contact's rest force along F_d equals |F_d| (``pose_at_depth(depth)`` the pose there), the arm
    put at rest there (``_rest_at``). Returns the joint positions."""
    plant, robot, space = systems.plant, systems.robot, systems.constraint_space
    kinematics = systems.controller.kinematics
    controller_context = kinematics.plant.CreateDefaultContext()

    def positions_at_depth(depth):
        return _positions_at(kinematics, controller_context, pose_at_depth(depth), joint_guess, depth, owner, what)

    def configuration(q):
        kinematics.plant.SetPositions(controller_context, q)
        task = kinematics.evaluate(controller_context)
        return task, space.evaluate(task.configuration, task.velocity)

    q_surface = positions_at_depth(0.0)
    task, values = configuration(q_surface)
    try:
        space.constraint.check_satisfied(task.configuration, tolerance)
    except OffConstraintError as error:
        raise OffConstraintError(f"{owner}: {what}: {error}") from None
    space.constraint.check_branch(task.configuration)
    mask = np.array([0.0 if i in space.constraint.kinematic_rows else 1.0 for i in range(space.force_size)])
    check_pushing_force(desired, force_controlled=mask, where=f"{owner} (desired_force)")
    magnitude = float(np.linalg.norm(desired))
    q0 = q_surface
    if magnitude > 0:
        plant_context = plant.GetMyMutableContextFromRoot(root_context)
        frame = plant.GetFrameByName(robot.end_effector_frame)
        pad = list(robot.pad_geometries)

        def pressing_force(depth):
            q = positions_at_depth(depth)
            plant.SetPositions(plant_context, robot.arm, q)
            p_WP = frame.CalcPoseInWorld(plant_context).multiply(np.asarray(robot.end_effector_point, dtype=float))
            task_at, values_at = configuration(q)
            wrench = space.chart.generalized_force(task_at.configuration,
                                                   rest_contact_wrench(plant, plant_context, pad, p_WP))
            return float(space.split_wrench(values_at, wrench)[1] @ desired) / magnitude - magnitude

        reached = {}                           # {depth: the pressing force's excess there} as evaluated

        def recorded_force(depth):
            reached[depth] = pressing_force(depth)
            return reached[depth]

        try:
            depth = pressing_depth(recorded_force, desired, max_depth, owner)
        except OffConstraintError as error:
            if max_depth not in reached:       # the start already penetrates: max_depth had no part in it
                raise
            # Nothing touched down to max_depth: a gap, or a max_depth too small to reach the contact.
            raise OffConstraintError(
                f"{owner}: the pad touches nothing down to max_depth = {max_depth:g} m beyond the start pose along "
                "the pressing direction: either max_depth is too small (raise it; the default is 0.01 m) or the "
                "workpiece's geometry is farther than the surface C = 0 (a gap: move the workpiece or the start so "
                "that they agree)") from error
        except ConfigError:                    # station.start.pressing_depth: too soft a contact for F_d
            if max_depth not in reached:
                raise
            raise ArgumentError(f"{owner}: max_depth = {max_depth:g} m of penetration presses with only "
                                f"{reached[max_depth] + magnitude:.3g} N, less than |desired_force| = {magnitude:.3g} "
                                "N: lower desired_force, raise max_depth or stiffen the pad (its hydroelastic "
                                "modulus)") from None
        q0 = positions_at_depth(depth)
    _rest_at(diagram, root_context, systems, q0, desired, owner)
    return q0
