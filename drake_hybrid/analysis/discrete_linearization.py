"""The sampled closed loop linearized: the Jacobian of its one-period map, whose multipliers see the control period.

* ``linearize_discrete``: a discrete closed loop (discrete plant, sampled controller) rebuilt with
  every discrete update at the same instants, so that Drake evaluates its one-period map x+ = f(x)
  directly (one period of actuation delay).
* ``linearize_sampled_loop``: the loop exactly as ``simulate`` runs it (zero-delay hold, sampled
  sensors), its map taken by simulating one period from perturbed states.

Both differentiate the map by central differences, map its multipliers mu to continuous-time
eigenvalues log(mu) / h and match those against the controller's designed ones (``analysis.design``,
``analysis.matching``). With SAP and hydroelastic contact the map is only piecewise smooth: a map
that looks unstable is differentiated again with a larger step (``StepCheck``). The continuous
closed loop's linearization is ``analysis.linearization``.
"""

import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

import numpy as np

from pydrake.systems.analysis import ApplySimulatorConfig, InitializeParams, Simulator

from drake_hybrid.analysis.design import PredictedEigenvalues, controller_prediction
from drake_hybrid.analysis.linearization import at_rest_config, checked_scenario_config, checked_stages, task_shifts
from drake_hybrid.analysis.matching import EigenvalueMatch, match_eigenvalues
from drake_hybrid.control.sampling import SAMPLE_LEAD
from drake_hybrid.core.arguments import nonnegative, number, positive, relative_tolerance
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.progress import StagesLike
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task import EigenvalueShift


def _one_period_jacobian(step, x0, epsilon):
    """Central-difference Jacobian of a one-period map ``step`` at x0, and max |step(x0) - x0|."""
    residual = float(np.max(np.abs(step(x0) - x0)))
    A = np.zeros((x0.size, x0.size))
    for j in range(x0.size):
        dx = np.zeros(x0.size)
        dx[j] = epsilon
        A[:, j] = (step(x0 + dx) - step(x0 - dx)) / (2 * epsilon)
    return A, residual


# A one-period map is only piecewise smooth with SAP and hydroelastic contact: at an equilibrium on
# a kink, small central-difference steps can show a multiplier outside the unit circle that the
# loop does not have. One found above this rate (1/s) is checked at a step ten times larger.
STEP_CHECK_RATE = 0.01
STEP_CHECK_FACTOR = 10.0


@dataclass
class StepCheck:
    """The second look at an unstable-looking one-period map: its worst real part (1/s) at
    ``epsilon`` and at ``larger_epsilon``; ``confirmed`` when both are above STEP_CHECK_RATE."""

    epsilon: float
    worst_real: float
    larger_epsilon: float
    larger_worst_real: float

    @property
    def confirmed(self) -> bool:
        return self.worst_real > STEP_CHECK_RATE and self.larger_worst_real > STEP_CHECK_RATE

    def summary(self) -> str:
        verdict = ("confirmed" if self.confirmed else
                   "NOT confirmed: the one-period map is not smooth at this equilibrium (a contact-solver kink), "
                   "so the linearization cannot decide; trust the simulation")
        return (f"step check: worst real part {self.worst_real:.3g} 1/s at step {self.epsilon:g}, "
                f"{self.larger_worst_real:.3g} 1/s at step {self.larger_epsilon:g}: {verdict}")

    def as_dict(self) -> Dict[str, Any]:
        return {"epsilon": self.epsilon, "worst_real": self.worst_real, "larger_epsilon": self.larger_epsilon,
                "larger_worst_real": self.larger_worst_real, "confirmed": self.confirmed}


def _map_eigenvalues(A, period):
    """The continuous-time equivalents log(mu) / period of A's multipliers (|mu| floored: a
    multiplier at 0, a pure delay, maps to a large negative real part instead of -inf)."""
    multipliers = np.linalg.eigvals(A)
    magnitude = np.maximum(np.abs(multipliers), np.finfo(float).tiny)
    return multipliers, (np.log(magnitude) + 1j * np.angle(multipliers)) / period


def _step_checked_jacobian(step, x0, epsilon, period):
    """(A, residual, StepCheck or None): the one-period map's Jacobian at ``epsilon``; if it has a
    rate above STEP_CHECK_RATE, the same at STEP_CHECK_FACTOR times the step, for the StepCheck."""
    A, residual = _one_period_jacobian(step, x0, epsilon)
    worst = float(np.max(_map_eigenvalues(A, period)[1].real))
    if worst <= STEP_CHECK_RATE:
        return A, residual, None
    larger = STEP_CHECK_FACTOR * epsilon
    A_larger, _ = _one_period_jacobian(step, x0, larger)
    return A, residual, StepCheck(epsilon, worst, larger, float(np.max(_map_eigenvalues(A_larger, period)[1].real)))


@dataclass
class DiscreteLinearization:
    A: np.ndarray                    # Jacobian of the one-period map x_{k+1} = f(x_k)
    multipliers: np.ndarray          # eig(A)
    eigenvalues: np.ndarray          # log(multipliers) / period: the equivalent continuous eigenvalues
    period: float
    equilibrium_residual: float      # max |f(x) - x| at the linearization point
    predicted: PredictedEigenvalues
    match: EigenvalueMatch
    wall_time: float
    shifts: List[EigenvalueShift] = field(default_factory=list)       # the task's predictions
    shifted_match: Optional[EigenvalueMatch] = None  # the match against the design with those shifts
    step_check: Optional[StepCheck] = None     # set when the map looked unstable: the check at a larger step


def linearize_discrete(config: ScenarioConfig, tolerance: float = 0.05, epsilon: float = 1e-6, settle_time: float = 0.0,
                       stages: Optional[StagesLike] = None) -> DiscreteLinearization:
    """Linearize a discrete closed loop (discrete SAP plant and sampled controller) at its equilibrium.

    For plants that only exist in discrete time (the crank: its SAP weld constraint needs a discrete
    plant). The closed loop is rebuilt with every discrete update at the same instants (the
    controller ticks at k h, one period of delay; the plant's output ports unsampled, so the state
    is just the plant's and the controller's), which makes it one map x+ = f(x) per period
    (``EvalUniquePeriodicDiscreteUpdate``). Its Jacobian is taken by central differences
    (``epsilon``; DRAKE_NOTES: much smaller is noisy with SAP), and the multipliers mu are mapped
    to continuous-time eigenvalues log(mu) / h. The one period of actuation delay shifts the
    designed eigenvalues by about lambda^2 h / 2 (0.5 % at -10 1/s and 1 kHz).

    ``settle_time`` (s): first simulate the rebuilt loop at rest for this long, so that the
    compliant constraint forces settle onto the equilibrium. ``stages`` (``core.progress.Stages``):
    one line per stage with its time.
    """
    owner = "linearize_discrete"
    checked_scenario_config(config, owner)
    relative_tolerance(tolerance, "tolerance", owner)
    positive(epsilon, "epsilon", owner)
    settle_time = nonnegative(settle_time, "settle_time", owner, unit="s")
    stages = checked_stages(stages, owner)
    c = at_rest_config(config, owner)
    if not c.plant.time_step > 0:
        raise ConfigError(f"{owner}: config.plant.time_step must be > 0 (a discrete plant), got {c.plant.time_step:g}")
    c.control_period = c.plant.time_step
    c.log_period = c.plant.time_step
    c.sensor.bandwidth_hz = 0.0
    with stages(f"{c.task}: building the discrete closed loop"):
        scenario = build_scenario(c, with_loggers=False, sampled_plant_outputs=False, controller_sample_lead=False)
        diagram = scenario.diagram
        assert diagram is not None                   # build_scenario returns it built
        simulator = Simulator(diagram)
        ApplySimulatorConfig(c.simulator, simulator)
        context = simulator.get_mutable_context()
    with stages(f"{c.task}: solving the start"):
        set_initial_conditions(scenario, context)
        simulator.Initialize()
    if settle_time > 0:
        with stages(f"{c.task}: settling at rest for {settle_time:g} s"):
            simulator.AdvanceTo(settle_time)
    if context.num_abstract_states() != 0 or context.num_continuous_states() != 0:
        raise ConfigError(f"{owner} needs a closed loop with discrete state only (no wrench filter or other "
                          "continuous or abstract state)")

    def state_vector(ctx):
        return np.concatenate([ctx.get_discrete_state(i).CopyToVector()
                               for i in range(ctx.num_discrete_state_groups())])

    def set_state(ctx, x):
        start = 0
        for i in range(ctx.num_discrete_state_groups()):
            size_i = ctx.get_discrete_state(i).size()
            ctx.SetDiscreteState(i, x[start:start + size_i])
            start += size_i

    def step(x):
        work = context.Clone()
        set_state(work, x)
        update = diagram.EvalUniquePeriodicDiscreteUpdate(work)
        return np.concatenate([update.get_vector(i).CopyToVector() for i in range(update.num_groups())])

    start = time.perf_counter()
    x0 = state_vector(context)
    with stages(f"{c.task}: linearizing (one-period map, {x0.size} states, {2 * x0.size} steps)"):
        A, residual, step_check = _step_checked_jacobian(step, x0, epsilon, c.plant.time_step)
    wall = time.perf_counter() - start
    multipliers = np.linalg.eigvals(A)
    h = c.plant.time_step
    # Multipliers at 0 (pure delays, e.g. the held torque) have no continuous-time counterpart.
    keep = np.abs(multipliers) > 1e-9
    eigenvalues = np.log(multipliers[keep].astype(complex)) / h
    predicted = controller_prediction(scenario.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    shifts, shifted_match = task_shifts(get_task(c.task), scenario, context, predicted, eigenvalues, tolerance)
    return DiscreteLinearization(A=A, multipliers=multipliers, eigenvalues=eigenvalues, period=h,
                                 equilibrium_residual=residual, predicted=predicted, match=match, wall_time=wall,
                                 shifts=shifts, shifted_match=shifted_match, step_check=step_check)



def linearize_sampled_loop(config: ScenarioConfig, epsilon: float = 1e-5, tolerance: float = 0.05,
                           periods: int = 1) -> DiscreteLinearization:
    """Jacobian of the simulated sampled closed loop's one-period map at its contact equilibrium.

    Unlike ``linearize_discrete`` (which rebuilds the loop with one period of actuation delay so
    that Drake evaluates its map directly), this differentiates the loop exactly as ``simulate``
    runs it, zero-delay hold and sampled sensors included, by simulating one period from perturbed
    states: slower, and only piecewise smooth with hydroelastic contact (below), but it is the
    loop whose stability a sweep over control periods asks about.

    The map takes the vector state x_k (plant q, v; controller xi, e_p and
    held torque) at t_k = k h - delta/2, between the controller's tick at
    k h - delta and the plant's step at k h (docs/design.md, "Sampling"), to
    x_{k+1} one control period h later, by simulating the full diagram. At that
    instant the plant's sampled contact results (abstract state) are overwritten
    by the step at k h before the next tick reads them, so x_k is the whole
    state of the loop and the map is a function of it alone. Its Jacobian is taken
    by central differences (``epsilon``, absolute, per state; about 1e-5 with
    SAP, smaller is noisy). Multipliers inside the unit circle mean a stable
    sampled loop: this sees the sampling, the zero-order hold and the SAP step
    that the continuous linearization cannot. ``eigenvalues`` are
    log(multipliers) / (periods h), matched against the designed continuous
    ones; ``periods`` > 1 differentiates the map over that many periods.

    Accuracy (window task, 5 MPa pad, 1 ms): the SAP solve and the tessellated
    contact surface make the map only piecewise smooth, so the slow rates
    (multipliers near 1) move by a few 1/s with ``epsilon`` (1e-4, 1e-5,
    1e-6: the velocity-loop rates between -3.6 and -10.7 1/s against the
    designed -10, -8; a -5.0 1/s mode in all). Multipliers far outside the
    unit circle (the stiff-contact force loop: |mu| 1.1 to 1.9) are robust.

    Needs a discrete plant, a sampled controller with a period that is a whole
    number of plant steps, and no wrench filter (a filter would sample the
    contact results at k h, where the stale abstract state would enter).

    ArgumentError for a ``config`` that is not a ScenarioConfig, an ``epsilon`` that is not > 0, a
    ``tolerance`` outside (0, 1], ``periods`` that is not an integer >= 1; ConfigError for a config
    without the loop above.
    """
    owner = "linearize_sampled_loop"
    checked_scenario_config(config, owner)
    positive(epsilon, "epsilon", owner)
    relative_tolerance(tolerance, "tolerance", owner)
    periods = number(periods, "periods", owner, low=1, integer=True, unit="control periods")
    h, time_step = float(config.control_period), float(config.plant.time_step)
    if not (time_step > 0 and h > 0):
        raise ConfigError(f"{owner} needs a discrete plant (time_step > 0) and a sampled controller "
                          f"(control_period > 0); got time_step = {time_step:g}, control_period = {h:g}")
    steps = h / time_step
    if abs(steps - round(steps)) > 1e-9 * steps:
        raise ConfigError(f"{owner} needs control_period to be a whole number of plant steps; "
                          f"got control_period = {h:g}, time_step = {time_step:g}")
    if config.sensor.bandwidth_hz > 0:
        raise ConfigError(f"{owner} needs sensor.bandwidth_hz = 0 (a sampled wrench filter reads the plant's "
                          "sampled contact results at the plant's steps, outside the map's vector state)")

    c = at_rest_config(config, owner)
    scenario = build_scenario(c, with_loggers=False)
    diagram = scenario.diagram
    assert diagram is not None                       # build_scenario returns it built
    base = diagram.CreateDefaultContext()
    set_initial_conditions(scenario, base)
    t_k = h * (1.0 - 0.5 * SAMPLE_LEAD)
    base.SetTime(t_k)
    groups = base.num_discrete_state_groups()
    sizes = [base.get_discrete_state(i).size() for i in range(groups)]
    continuous_size = base.num_continuous_states()

    def get_state(context):
        parts = [context.get_discrete_state(i).CopyToVector() for i in range(groups)]
        if continuous_size:
            parts.append(context.get_continuous_state_vector().CopyToVector())
        return np.concatenate(parts)

    def one_period(x):
        context = base.Clone()
        offset = 0
        for i, size in enumerate(sizes):
            context.SetDiscreteState(i, x[offset:offset + size])
            offset += size
        if continuous_size:
            context.SetContinuousState(x[offset:])
        simulator = Simulator(diagram, context)
        # No initialization events: they would recompute the held torque from the stale sensor reading.
        simulator.Initialize(InitializeParams(suppress_initialization_events=True))
        simulator.AdvanceTo(t_k + periods * h)
        return get_state(context)

    start = time.perf_counter()
    A, residual, step_check = _step_checked_jacobian(one_period, get_state(base), epsilon, periods * h)
    wall = time.perf_counter() - start
    # Multipliers at 0 (the held torque is recomputed every tick) have no continuous counterpart.
    multipliers, eigenvalues = _map_eigenvalues(A, periods * h)
    predicted = controller_prediction(scenario.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    return DiscreteLinearization(A=A, multipliers=multipliers, eigenvalues=eigenvalues, period=h,
                                 equilibrium_residual=residual, predicted=predicted, match=match, wall_time=wall,
                                 step_check=step_check)
