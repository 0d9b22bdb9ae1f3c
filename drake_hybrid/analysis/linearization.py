"""Drake's ``Linearize`` of a continuous closed loop at its contact equilibrium: a task's, or your own diagram's.

* ``linearize_continuous``: a task's closed loop made continuous (``equilibrium_config``: continuous
  plant and controller, a low-pass on the wrench, no friction; at rest, ``at_rest_config``), its
  start set, linearized at that contact equilibrium.
* ``linearize_at_contact``: your own continuous diagram, at the contact equilibrium its context holds
  (``check_equilibrium`` first: NotAtEquilibriumError naming the likely cause otherwise).

Both check Drake's A (AutoDiffXd) against central differences (``analysis.derivatives``), match eig(A)
against the controller's designed eigenvalues (``analysis.design``, ``analysis.matching``), and also
against the design with the task's or the contact's predicted shifts (``analysis.environment``), and
name every unstable mode with its likely cause (``analysis.modes``). The sampled loop's linearization
(its one-period map) is ``analysis.discrete_linearization``.
"""

import copy
import dataclasses
import time
from dataclasses import dataclass, field
from typing import List, Optional, Tuple, cast

import numpy as np

from pydrake.systems.framework import Context, Diagram
from pydrake.systems.primitives import Linearize

from drake_hybrid.analysis.derivatives import JACOBIAN_TOLERANCE, JacobianCheck, checked_state_jacobian
from drake_hybrid.analysis.design import PredictedEigenvalues, controller_prediction
from drake_hybrid.analysis.environment import impedance_environment_shifts
from drake_hybrid.analysis.matching import EigenvalueMatch, match_eigenvalues, shifted_design
from drake_hybrid.analysis.modes import ModeDiagnosis, diagnose_unstable_modes
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.arguments import boolean, function, instance, positive, relative_tolerance, text
from drake_hybrid.core.errors import ArgumentError, NotAtEquilibriumError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.progress import StagesLike, quiet
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.root_context import check_root_context
from drake_hybrid.systems.faults import SensorFaultConfig
from drake_hybrid.systems.sources import Profile
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task import EigenvalueShift, Scenario, Task


def task_shifts(task: Optional[Task], scenario: HybridSystems, root_context: Context, predicted: PredictedEigenvalues,
                measured: Array, tolerance: float) -> Tuple[List[EigenvalueShift], Optional[EigenvalueMatch]]:
    """The predicted shifts and the match against the shifted design (no shifts, no match): the
    task's own (physics the paper's model leaves out, e.g. the crank's handle inertia; ``task`` None:
    none), or else, in impedance-force mode, those of the impedance meeting its contact's stiffness
    and damping (``analysis.environment``)."""
    # A task's shifts are asked of its own Scenario (linearize_continuous builds it).
    shifts = task.eigenvalue_shifts(cast(Scenario, scenario), root_context) if task is not None else []
    if not shifts and scenario.controller.mode is ControlMode.IMPEDANCE_FORCE:
        shifts = impedance_environment_shifts(scenario, root_context, predicted.designed, tolerance=tolerance)
    if not shifts:
        return [], None
    match = match_eigenvalues(shifted_design(predicted.designed, shifts), measured, tolerance=tolerance,
                              marginal=predicted.marginal)
    return shifts, match



def at_rest_config(config: ScenarioConfig, owner: str = "at_rest_config") -> ScenarioConfig:
    """A copy of ``config`` at rest, its sampling kept: zero desired velocity, constant F_d(0), zero
    start integrals, starting in contact, no contact supervisor, sensor faults or wrench conditioner
    (sampled systems outside the law, with their own timing); the model error is kept; a job's path
    held at a point (``path.hold_at``, its first point unless set). Its start is an equilibrium of
    the closed loop. ArgumentError (naming ``owner``) for a ``config`` that is not a ScenarioConfig."""
    c = copy.deepcopy(checked_scenario_config(config, owner))
    size = get_task(c.task).constraint_space(c).velocity_size
    c.desired_velocity = Profile(kind="constant", value=[0.0] * size)
    c.desired_force = Profile(kind="constant", value=list(c.desired_force.evaluate(0.0)[0]))
    c.start.force_integral = []
    c.start.position_error = []
    c.start.in_contact = True
    c.supervision.enabled = False
    c.sensor_faults = SensorFaultConfig()
    c.sensor.condition = False
    if c.path.active and c.path.hold_at < 0:     # a job's path: held at its first point (path.hold_at)
        c.path.hold_at = 0.0
    return c


def equilibrium_config(config: ScenarioConfig, bandwidth_hz: float = 200.0,
                       owner: str = "equilibrium_config") -> ScenarioConfig:
    """The continuous-time version of ``at_rest_config(config)``: continuous plant and controller,
    a low-pass on the wrench (to break the algebraic loop), and no friction.

    Friction is removed because at rest it sticks: the pad is then held in the tangent directions
    by the contact, not by the designed loop, whose modes become marginal (DRAKE_NOTES); the
    designed loop is the paper's frictionless one (section 3.1). ArgumentError (naming ``owner``) for a
    ``config`` that is not a ScenarioConfig, a ``bandwidth_hz`` that is not a finite number > 0."""
    checked_scenario_config(config, owner)
    bandwidth_hz = positive(bandwidth_hz, "bandwidth_hz", owner, unit="Hz")
    c = at_rest_config(config, owner)
    c.plant.time_step = 0.0
    c.control_period = 0.0
    c.contact.friction = 0.0
    if not c.sensor.bandwidth_hz > 0:
        c.sensor.bandwidth_hz = bandwidth_hz
    return c


@dataclass
class Linearization:
    A: np.ndarray
    eigenvalues: np.ndarray
    equilibrium_residual: float        # max |x-dot| at the linearization point
    predicted: PredictedEigenvalues
    match: EigenvalueMatch
    wall_time: float
    shifts: List[EigenvalueShift] = field(default_factory=list)       # the task's predictions
    shifted_match: Optional[EigenvalueMatch] = None  # the match against the design with those shifts
    jacobian_check: Optional[JacobianCheck] = None   # AutoDiffXd against central differences; which A is used
    unstable_modes: List[ModeDiagnosis] = field(default_factory=list)   # real part > 0.01 1/s


def checked_stages(stages: Optional[StagesLike], owner: str) -> StagesLike:
    """``stages`` (a ``core.progress.Stages``, or None: silent) checked, naming ``owner``."""
    function(stages, "stages", owner, "stages(label) -> a context manager (core.progress.Stages)", allow_none=True)
    return stages or quiet()


def checked_scenario_config(config: ScenarioConfig, owner: str) -> ScenarioConfig:
    """``config`` if it is a ScenarioConfig; ArgumentError naming ``owner`` otherwise."""
    return instance(config, "config", owner, ScenarioConfig,
                    what="a ScenarioConfig (e.g. get_task(name).default_config())")


def linearize_continuous(config: ScenarioConfig, tolerance: float = 0.05, bandwidth_hz: float = 200.0,
                         stages: Optional[StagesLike] = None, jacobian_tolerance: float = JACOBIAN_TOLERANCE,
                         require_equilibrium: bool = True) -> Linearization:
    """Linearize the continuous closed loop of ``config`` at its contact equilibrium.

    Builds ``equilibrium_config(config)``, sets the start, checks it is an
    equilibrium, runs Drake's ``Linearize`` (AutoDiffXd through plant,
    contact, sensor, filter and controller), checks its A against central
    differences of the time derivatives, every column (``analysis.derivatives``:
    where they disagree beyond ``jacobian_tolerance``, relative per column, the
    central-difference A is used, ``jacobian_check.used`` says so and a
    ``DerivativeMismatchWarning`` is issued), and matches eig(A) against the
    designed eigenvalues. ``wall_time`` covers both derivatives. Every mode with real part
    above 0.01 1/s is named with its likely cause (``unstable_modes``, ``analysis.modes``).
    ``stages`` (``core.progress.Stages``): one line per stage with its time. ``tolerance`` (relative, in
    (0, 1]), ``jacobian_tolerance`` and ``require_equilibrium`` as for ``linearize_at_contact``.
    """
    owner = "linearize_continuous"
    checked_scenario_config(config, owner)
    relative_tolerance(tolerance, "tolerance", owner)
    stages = checked_stages(stages, owner)
    c = equilibrium_config(config, bandwidth_hz, owner)
    with stages(f"{c.task}: building the continuous closed loop"):
        scenario = build_scenario(c, with_loggers=False)
        diagram = scenario.diagram
        assert diagram is not None                   # build_scenario returns it built
        context = diagram.CreateDefaultContext()
    with stages(f"{c.task}: solving the start (contact equilibrium)"):
        set_initial_conditions(scenario, context)
    return linearize_at_contact(diagram, context, scenario, tolerance=tolerance,
                                jacobian_tolerance=jacobian_tolerance, stages=stages, task=scenario.task,
                                what=c.task, require_equilibrium=require_equilibrium)


# The largest max |x-dot| (per second) accepted at a linearization point, relative to the state's size
# max(1, max |x|) (the filter's N, the joints' rad): 1 % per second. Measured at the package's own
# equilibria (``equilibrium_config`` of every continuous registered task in every mode, after
# ``set_initial_conditions``): 1.2e-10 to 3.3e-10 in velocity- and position-force; in impedance-force
# 6.1e-4 (surface polishing, max |x| 8.8) and 4.5e-3 (sphere polishing, max |x| 7), i.e. at most 6.4e-4 of
# the state's size per second. Off equilibrium (a Kinova Jaco on a cylinder, F_d 10 N): commanded to slide
# at 3 cm/s 1.08 (about 0.1 of its size), solve_contact_start forgotten 28.6, a wrist sensor on a
# continuous plant 593 (565 with hydroelastic_with_fallback).
EQUILIBRIUM_RATE = 0.01


def _largest_rates(diagram, root_context):
    """[(max |x-dot| of a subsystem's continuous state, its name)], largest first."""
    rates = []
    for system in diagram.GetSystems():
        context = system.GetMyContextFromRoot(root_context)
        if context.num_continuous_states():
            rate = np.max(np.abs(system.EvalTimeDerivatives(context).CopyToVector()))
            rates.append((float(rate), system.get_name()))
    return sorted(rates, reverse=True)


# The held (kinematic) rows' residual above which a start's orientation is off them (C's units: a sine, rad).
HELD_ROWS_RESIDUAL = 1e-6


def _held_rows_off(controller, controller_context):
    """'C[i] = ...' for each kinematic row of the controller's constraint off zero by more than
    HELD_ROWS_RESIDUAL at the context, joined; '' if none is."""
    rows = list(controller.kinematic_rows)
    if not rows:
        return ""
    values = np.asarray(controller.GetOutputPort("constraint_value").Eval(controller_context), dtype=float)
    return ", ".join(f"C[{i}] = {values[i]:.3g}" for i in rows if abs(values[i]) > HELD_ROWS_RESIDUAL)


def check_equilibrium(diagram: Diagram, root_context: Context, systems: HybridSystems, what: str = "your diagram",
                      owner: str = "check_equilibrium") -> float:
    """max |x-dot| of the continuous state at ``root_context``; NotAtEquilibriumError if it is above
    EQUILIBRIUM_RATE (1/s) times the state's size max(1, max |x|), naming the subsystem where it is
    largest and the likely cause: a desired velocity that is not zero, a wrist force/torque sensor on
    a continuous plant, the constraint's held rows not zero (the tool turned off them), or else the start
    not solved (``solve_contact_start`` / ``prime_start`` not called, or the state changed after it). ArgumentError (naming ``owner``) for a ``diagram``,
    ``root_context`` and ``systems`` that do not belong together (``station.root_context``)."""
    where = f"{owner}({text(what, 'what', owner)})"
    check_root_context(diagram, root_context, systems, where)
    derivatives = diagram.EvalTimeDerivatives(root_context).CopyToVector()
    residual = float(np.max(np.abs(derivatives))) if derivatives.size else 0.0
    state = root_context.get_continuous_state_vector().CopyToVector()
    scale = max(1.0, float(np.max(np.abs(state)))) if state.size else 1.0
    if not residual > EQUILIBRIUM_RATE * scale:
        return residual
    controller = systems.controller
    controller_context = controller.GetMyContextFromRoot(root_context)
    velocity = controller.get_desired_velocity_input_port().Eval(controller_context)
    held_rows = _held_rows_off(controller, controller_context)
    if np.any(np.asarray(velocity) != 0):
        cause = (f"the controller is commanded to move (desired_velocity = {np.round(velocity, 6).tolist()}): "
                 "linearize with a zero desired velocity")
    elif isinstance(systems.sensor, WristForceTorqueSensor):
        cause = ("a WristForceTorqueSensor on a continuous plant: its reading is not the contact's at rest; use the "
                 "contact sensor (sensor=None) for the continuous loop")
    elif held_rows:
        cause = (f"the constraint's held rows are not zero at the start ({held_rows}): the controller turns the tool "
                 "onto them, so the start is not at rest; start with the orientation they want (solve_contact_start "
                 "and solve_path_start turn it so), and change no state after it")
    else:
        cause = ("the start is not solved: call station.contact_start.solve_contact_start (or prime_start after "
                 "setting the arm at rest pressing with F_d) on this context, and change no state after it")
    rate, name = _largest_rates(diagram, root_context)[0]
    raise NotAtEquilibriumError(
        f"{where}: the state is not an equilibrium: max |x-dot| = {residual:.3g} (largest in "
        f"'{name}', {rate:.3g}) > {EQUILIBRIUM_RATE:g}/s x the state's size {scale:.3g}, so its eigenvalues would "
        f"not be the design's; likely cause: {cause} (require_equilibrium=False linearizes there anyway)")


def linearize_at_contact(diagram: Diagram, root_context: Context, systems: HybridSystems, tolerance: float = 0.05,
                         jacobian_tolerance: float = JACOBIAN_TOLERANCE, stages: Optional[StagesLike] = None,
                         task: Optional[Task] = None, what: str = "your diagram",
                         require_equilibrium: bool = True) -> Linearization:
    """Linearize your continuous closed loop at the contact equilibrium ``root_context`` holds (e.g.
    after ``station.contact_start.solve_contact_start``), with what ``drake-hybrid analyze`` reports.

    ``systems``: the ``HybridSystems`` of ``station.loop.add_hybrid_controller`` (or a built
    ``Scenario``). The diagram must be purely continuous (a plant with ``time_step=0``, a controller
    without ``control_period``, a wrench low-pass). Runs Drake's ``Linearize`` (AutoDiffXd through
    plant, contact, sensor, filter and controller), checks its A against central differences of the
    time derivatives, every column (``analysis.derivatives``: beyond ``jacobian_tolerance``, relative
    per column, the central-difference A is used and ``jacobian_check.used`` says so), matches eig(A)
    against the controller's designed eigenvalues within ``tolerance`` (``analysis.design.controller_prediction``), in
    impedance-force mode also against the design shifted by the contact's measured stiffness and
    damping (``analysis.environment``; ``task``: a Task whose own shifts come first), and names every
    mode with real part above 0.01 1/s with its likely cause (``analysis.modes``). Returns a
    Linearization; ``equilibrium_residual`` is max |x-dot| at the start (near 0 at an equilibrium).

    The state must be an equilibrium (``check_equilibrium``: max |x-dot| at most EQUILIBRIUM_RATE = 1 %
    per second of the state's size, else NotAtEquilibriumError naming the likely cause: a desired
    velocity that is not zero, the start not solved, a wrist sensor on a continuous plant);
    ``require_equilibrium=False`` linearizes anywhere. ArgumentError for a ``tolerance`` outside (0, 1],
    a ``jacobian_tolerance`` that is not > 0 (inf: never replace a column), a ``diagram``,
    ``root_context`` and ``systems`` that do not belong together (``station.root_context``)."""
    owner = f"linearize_at_contact({text(what, 'what', 'linearize_at_contact')})"
    check_root_context(diagram, root_context, systems, owner)
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    jacobian_tolerance = positive(jacobian_tolerance, "jacobian_tolerance", owner, allow_infinite=True,
                                  unit="relative column error")
    stages = checked_stages(stages, owner)
    require_equilibrium = boolean(require_equilibrium, "require_equilibrium", owner)
    if task is not None and not hasattr(task, "eigenvalue_shifts"):
        raise ArgumentError(f"{owner}: task must be a Task (scenario.task) or None, got {type(task).__name__}")
    if not (root_context.num_abstract_states() == 0 and root_context.has_only_continuous_state()):
        raise ArgumentError(f"{owner}: the closed loop must be purely continuous (a plant with time_step=0, a "
                            "controller without control_period); it has discrete or abstract state")
    if require_equilibrium:
        residual = check_equilibrium(diagram, root_context, systems, what, "linearize_at_contact")
    else:
        derivatives = diagram.EvalTimeDerivatives(root_context).CopyToVector()
        residual = float(np.max(np.abs(derivatives))) if derivatives.size else 0.0
    start = time.perf_counter()
    with stages(f"{what}: linearizing ({root_context.num_continuous_states()} states, AutoDiffXd)"):
        linear = Linearize(diagram, root_context, equilibrium_check_tolerance=np.inf)
    with stages(f"{what}: checking A against central differences"):
        A, check = checked_state_jacobian(diagram, root_context, linear.A(), tolerance=jacobian_tolerance,
                                          what=f"linearize_at_contact({what})")
    wall = time.perf_counter() - start
    eigenvalues = np.linalg.eigvals(A)
    predicted = controller_prediction(systems.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    shifts, shifted_match = task_shifts(task, systems, root_context, predicted, eigenvalues, tolerance)
    view = systems if getattr(systems, "diagram", None) is not None else dataclasses.replace(systems, diagram=diagram)
    modes = diagnose_unstable_modes(view, root_context, A, systems.controller.mode, predicted.designed)
    return Linearization(A=A, eigenvalues=eigenvalues, equilibrium_residual=residual, predicted=predicted,
                         match=match, wall_time=wall, shifts=shifts, shifted_match=shifted_match,
                         jacobian_check=check, unstable_modes=modes)
