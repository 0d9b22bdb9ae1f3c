"""End-effector kinematics in chart coordinates, from a MultibodyPlant.

``EndEffectorKinematics`` turns Drake's geometric quantities of an
end-effector point P fixed in a frame E (pose, geometric Jacobian J_g, bias
spatial acceleration J_g-dot v) into the chart's x, nu, analytic Jacobian J
and J-dot q-dot (docs/theory.md §1). Works for float and AutoDiffXd
plants; frames are resolved by index, so the same object can be rebuilt on a
scalar-converted plant with ``for_plant``.
"""

from dataclasses import dataclass
from typing import Any, Callable, Iterable, List, Optional, Tuple, Union, cast

import numpy as np
from numpy.typing import ArrayLike

from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, FrameIndex, JacobianWrtVariable
from pydrake.systems.framework import CacheEntry, Context, InputPort, LeafSystem, ValueProducer

from drake_hybrid.core.arguments import describe, instance, joint_vector, number, positive, vector
from drake_hybrid.core.charts import Chart
from drake_hybrid.core.errors import ArgumentError, DimensionError, UnknownFrameError, UnreachablePoseError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.linalg import all_finite, value

# A plant, its context, a frame or a system of either scalar type (float or AutoDiffXd). pydrake's stubs name
# the AutoDiffXd classes (MultibodyPlant_[AutoDiffXd], ...) in a way a type checker cannot read: they are Any.
AnyScalarPlant = Union[MultibodyPlant, Any]
AnyScalarContext = Union[Context, Any]
AnyScalarFrame = Union[Frame, Any]
AnyScalarSystem = Union[LeafSystem, Any]


@dataclass
class TaskKinematics:
    """Chart quantities of the end-effector point at one plant state."""

    configuration: Array        # x (the paper's r)
    velocity: Array             # nu = J q-dot (the paper's r-dot)
    jacobian: Array             # J (d x n)
    bias: Array                 # J-dot q-dot (d)
    rotation: Array             # R_WE (3 x 3)
    position: Array             # p_WP (3)
    spatial_jacobian: Array     # J_g (6 x n), rows [omega; v]


def frame_names(plant: AnyScalarPlant) -> List[str]:
    """Names of all frames of ``plant`` (for error messages)."""
    return sorted({plant.get_frame(FrameIndex(i)).name() for i in range(plant.num_frames())})


def resolve_frame(plant: AnyScalarPlant, frame: Union[AnyScalarFrame, str], what: str = "end_effector_frame"
                  ) -> AnyScalarFrame:
    """The Frame of ``plant`` given one of its Frames or a frame name (the argument ``what``). Raises
    UnknownFrameError naming the plant's frames if it is not there, ArgumentError for anything else."""
    if isinstance(frame, str):
        if not plant.HasFrameNamed(frame):
            raise UnknownFrameError(f"{what}: frame '{frame}' is not in the plant; its frames are {frame_names(plant)}")
        return plant.GetFrameByName(frame)
    try:
        name = frame.name()
        parent = frame.GetParentPlant()
    except AttributeError:
        raise ArgumentError(f"{what} must be a Frame of the plant or a frame name, got {describe(frame)}") from None
    if parent is not plant:
        same_name = " (the plant has a frame of that name: pass the name, or plant.GetFrameByName)" if \
            plant.HasFrameNamed(name) else f"; the plant's frames are {frame_names(plant)}"
        raise UnknownFrameError(f"{what}: frame '{name}' is a Frame of another plant, not of this one{same_name}")
    return frame


class EndEffectorKinematics:
    """Chart coordinates of the point P (``point_in_frame`` = p_EP) of frame E.

    Args:
        plant: a finalized MultibodyPlant (float or AutoDiffXd) with nq == nv.
        frame: the end-effector frame E (a Frame of ``plant`` or its name).
        point_in_frame: p_EP, the end-effector point in E (m).
        chart: the coordinate chart; the end-effector orientation is E's.
    """

    def __init__(self, plant: AnyScalarPlant, frame: Union[AnyScalarFrame, str], point_in_frame: ArrayLike,
                 chart: Chart) -> None:
        if not plant.is_finalized():
            raise ValueError("EndEffectorKinematics: the plant must be finalized")
        if plant.num_positions() != plant.num_velocities():
            raise ValueError(
                f"EndEffectorKinematics needs q-dot = v (nq == nv); the plant has nq = {plant.num_positions()}, "
                f"nv = {plant.num_velocities()}")
        point = vector(point_in_frame, "point_in_frame", "EndEffectorKinematics", 3, unit="m", error=DimensionError)
        self.plant = plant
        self.frame = resolve_frame(plant, frame)
        self.point_in_frame = point
        self.chart = chart
        self._world = plant.world_frame()

    def for_plant(self, plant: AnyScalarPlant) -> "EndEffectorKinematics":
        """The same kinematics on another scalar type of the same plant."""
        return EndEffectorKinematics(plant, plant.get_frame(self.frame.index()), self.point_in_frame, self.chart)

    def evaluate(self, plant_context: AnyScalarContext, check: bool = True) -> TaskKinematics:
        """TaskKinematics at the state in ``plant_context``."""
        plant = self.plant
        X_WE = plant.CalcRelativeTransform(plant_context, self._world, self.frame)
        R_WE: Array = X_WE.rotation().matrix()
        p_WP = X_WE.translation() + R_WE @ self.point_in_frame
        J_spatial: Array = plant.CalcJacobianSpatialVelocity(
            plant_context, JacobianWrtVariable.kV, self.frame, self.point_in_frame, self._world, self._world)
        A_bias = plant.CalcBiasSpatialAcceleration(
            plant_context, JacobianWrtVariable.kV, self.frame, self.point_in_frame, self._world, self._world
        ).get_coeffs()
        v = plant.GetVelocities(plant_context)
        chart = self.chart
        x = chart.configuration(R_WE, p_WP)
        if check:
            chart.check(x)
        nu = chart.task_velocity(x, J_spatial @ v)
        return TaskKinematics(
            configuration=x,
            velocity=nu,
            jacobian=chart.task_jacobian(x, J_spatial),
            bias=chart.task_bias(x, nu, A_bias),
            rotation=R_WE,
            position=p_WP,
            spatial_jacobian=J_spatial,
        )


def set_plant_state(system: AnyScalarSystem, plant: AnyScalarPlant, state_port: InputPort, context: AnyScalarContext,
                    plant_context: AnyScalarContext) -> Array:
    """Set ``plant_context``'s positions and velocities to ``state_port``'s [q; v] at ``context``
    and return [q; v]; ValueError naming ``system`` and the port if it is not finite."""
    state = cast(Array, state_port.Eval(context))
    if not all_finite(state):
        # Drake's SetPositionsAndVelocities aborts on a non-finite state; say which input it was.
        raise ValueError(f"{system.get_name() or type(system).__name__}: input '{state_port.get_name()}' has "
                         f"non-finite entries {value(state).tolist()}")
    plant.SetPositionsAndVelocities(plant_context, state)
    return state


def declare_plant_context_cache(system: AnyScalarSystem, plant: AnyScalarPlant, state_port: InputPort) -> CacheEntry:
    """Declare, on ``system``, a cache entry holding a context of ``plant`` whose
    positions and velocities are those on ``state_port`` ([q; v]).

    Per-context plant state lives in the system's cache (as in Drake's
    JointStiffnessController), never in a member shared by every context.
    Returns the CacheEntry; ``entry.Eval(context)`` is the plant context.
    """

    def calc(context, abstract_value):
        set_plant_state(system, plant, state_port, context, abstract_value.get_mutable_value())

    return system.DeclareCacheEntry(
        description="plant context",
        value_producer=ValueProducer(allocate=lambda: AbstractValue.Make(plant.CreateDefaultContext()), calc=calc),
        prerequisites_of_calc={state_port.ticket()})


def declare_cached_value(system: AnyScalarSystem, description: str, compute: Callable[[Any], Any],
                         prerequisites: Iterable[Any]) -> CacheEntry:
    """Declare, on ``system``, a cache entry holding the Python object ``compute(context)``,
    recomputed only when one of ``prerequisites`` (cache tickets) changes. Returns the CacheEntry."""
    return system.DeclareCacheEntry(
        description=description,
        value_producer=ValueProducer(allocate=lambda: AbstractValue.Make(object()),
                                     calc=lambda context, abstract_value: cast(AbstractValue, abstract_value).set_value(
                                         compute(context))),
        prerequisites_of_calc=set(prerequisites))


def declare_task_input(system: AnyScalarSystem, T: type, plant: MultibodyPlant, end_effector_frame: Union[Frame, str],
                       end_effector_point: ArrayLike, chart: Chart, plant_context_cache: bool = True
                       ) -> Tuple[Frame, EndEffectorKinematics, InputPort, Optional[CacheEntry]]:
    """The end-effector input of a system that reads the robot's state: declares the
    ``estimated_state`` input ([q; v]) and (unless ``plant_context_cache`` is False: the system keeps
    its plant context itself, see ``set_plant_state``) the per-context plant-context cache on ``system``.

    Returns (frame, kinematics, state_port, plant_context_cache or None): ``frame`` resolved on the
    float ``plant``, ``kinematics`` an EndEffectorKinematics on the plant of scalar type T.
    """
    frame = resolve_frame(plant, end_effector_frame)
    plant_T: AnyScalarPlant = plant if T == float else plant.ToAutoDiffXd()
    kinematics = EndEffectorKinematics(plant_T, plant_T.get_frame(frame.index()), end_effector_point, chart)
    state_port = system.DeclareVectorInputPort("estimated_state", 2 * plant.num_velocities())
    cache = declare_plant_context_cache(system, plant_T, state_port) if plant_context_cache else None
    return frame, kinematics, state_port, cache


def inverse_kinematics(kinematics: EndEffectorKinematics, plant_context: Context, X_target: RigidTransform,
                       q_guess: ArrayLike, tolerance: float = 1e-12, max_iterations: int = 200) -> Array:
    """Joint positions that put the end-effector pose at ``X_target`` (RigidTransform of E with
    its point P at X_target's origin), by damped Gauss-Newton from ``q_guess``.

    Uses the world-frame pose error [log(R_target R^T); p_target - p] and J_g, so it works for
    every chart; for a redundant arm it moves as little as possible from ``q_guess``. Steps are
    limited to 0.2 rad, the result is wrapped to the turn nearest ``q_guess`` and checked against
    the plant's position limits. Raises ValueError if it does not converge or violates a limit;
    ArgumentError (before any Drake call) for a ``kinematics`` that is not an EndEffectorKinematics, a
    ``plant_context`` not of its plant, an ``X_target`` that is not a RigidTransform, a ``q_guess`` that
    is not a vector of the plant's number of finite positions, a ``tolerance`` that is not a positive
    number, a ``max_iterations`` that is not an integer >= 1.
    """
    owner = "inverse_kinematics"
    plant = instance(kinematics, "kinematics", owner, EndEffectorKinematics).plant
    try:
        plant.ValidateContext(plant_context)
    except (RuntimeError, TypeError):
        raise ArgumentError(f"{owner}: plant_context must be a context of kinematics.plant "
                            f"(plant.CreateDefaultContext()), got {describe(plant_context)}") from None
    instance(X_target, "X_target", owner, RigidTransform)
    q_guess = joint_vector(q_guess, "q_guess", owner, plant)
    tolerance = positive(tolerance, "tolerance", owner)
    max_iterations = number(max_iterations, "max_iterations", owner, low=1, integer=True)
    q = q_guess.copy()
    target_R = X_target.rotation()
    target_p = X_target.translation()
    error_norm = np.inf
    for _ in range(max_iterations):
        plant.SetPositions(plant_context, q)
        task = kinematics.evaluate(plant_context, check=False)
        R_error = target_R.multiply(RotationMatrix(task.rotation).inverse()).ToAngleAxis()
        error = np.concatenate([R_error.angle() * R_error.axis(), target_p - task.position])
        error_norm = float(np.linalg.norm(error))
        if error_norm < tolerance:
            break
        J = task.spatial_jacobian
        step = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), error)
        largest = np.max(np.abs(step))
        q = q + (step * (0.2 / largest) if largest > 0.2 else step)
    if error_norm > 1e-8:
        raise UnreachablePoseError(f"inverse kinematics did not converge (pose error {error_norm:.3g}); is the target "
                                   "reachable?")
    # Revolute joints: the same pose on the turn nearest the guess.
    q = q_guess + np.remainder(q - q_guess + np.pi, 2 * np.pi) - np.pi
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    if np.any(q < lower - 1e-9) or np.any(q > upper + 1e-9):
        raise UnreachablePoseError(f"inverse kinematics: the solution {np.round(q, 3).tolist()} violates the joint "
                                   f"limits [{np.round(lower, 3).tolist()}, {np.round(upper, 3).tolist()}]")
    return q
