"""The kinematic instability of the Raibert-Craig hybrid controller, reproduced.

Setting (An & Hollerbach 1989; Fisher & Mujtaba 1992): a planar two-link arm
(``models/planar_2r.sdf``, 1.0 and 0.8 m) whose tip is position-controlled along one Cartesian axis
(the selection S picks x) and force-controlled along the other (z), with nothing to push on
(F_d = 0, no contact): the setting of the first-order joint-servo model, where any instability is
kinematic. The model is exact (the controllers' plant is the simulated one).

* Raibert-Craig (``control.baselines.JointServoHybridController``, mapping J^-1 S) with unequal
  joint gains K_q: the first-order model dq-dot = -K_q J^-1 S J dq has the rate
  mu = e_x^T J K_q J^-1 e_x (the nonzero eigenvalue of K_q J^-1 S J), which is negative on part of
  the workspace; with the joint servo K_s the pair s^2 + K_s s + K_s mu = 0 then has a root in the
  right half-plane (``analytic_eigenvalues``).
* Fisher-Mujtaba ((S J)^+ S) with the same gains, and Li & Sastry (``HybridController``,
  position-force mode, K_v and K_p giving poles in the joint gains' range): stable. So is the
  manipulation course's PD (``AxisPDOpenLoopForceController`` with K = K_p, D = K_v): with the
  force direction free its x row closes as Li & Sastry's design.

``linearized_eigenvalues`` is Drake's ``Linearize`` of the whole closed loop (plant and controller
in AutoDiffXd); ``simulated_growth_rate`` simulates it from a small perturbation and fits the growth
of the unstable mode's coordinate; ``stability_map`` evaluates the first-order model over the
configuration space.
"""

from dataclasses import dataclass

import numpy as np

from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Linearize

from drake_hybrid.analysis.design import predicted_eigenvalues
from drake_hybrid.control.baselines import (AxisPDOpenLoopForceController, JointServoHybridController,
                                            joint_servo_eigenvalues)
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.arguments import joint_vector
from drake_hybrid.core.charts import PlanarPointChart
from drake_hybrid.core.constraints import Constraint
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.core.projections import ConstraintSpace, GivenVelocityProjection
from drake_hybrid.station.loop import connect_hybrid_loop
from drake_hybrid.station.parsing import ConfigureParser, add_model
from drake_hybrid.systems.sources import Profile, ProfileSource

HINTED_CONFIGURATION = np.radians([-160.0, 30.0])   # rad: a configuration where Raibert-Craig (JOINT_GAINS) is unstable
JOINT_GAINS = (5.0, 1.0)                            # K_q (1/s): unequal joint gains
SERVO_RATE = 200.0                                  # K_s (1/s): the joint velocity servo
# Li & Sastry in position-force mode with the same bandwidth: s^2 + 6 s + 5 = (s + 1)(s + 5), the
# joint gains' range.
LI_SASTRY_GAINS = HybridGains(velocity=[6.0], position=[5.0], force_proportional=[0.5], force_integral=[15.0])
CONTROLLERS = ("raibert-craig", "fisher-mujtaba", "li-sastry", "pd-open-loop-force")


@dataclass
class TwoLinkLoop:
    """The closed loop of one controller on the two-link arm, at rest at ``q0``."""

    diagram: object
    plant: object
    controller: object
    context: object
    q0: np.ndarray


def two_link_plant(builder=None):
    """The continuous planar 2R plant (base welded to the world), finalized; (plant, builder)."""
    builder = builder if builder is not None else DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    parser = Parser(plant)
    ConfigureParser(parser)
    arm = add_model(parser, "planar_2r.sdf")[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", arm), RigidTransform())
    plant.Finalize()
    return plant, builder


def tip_position(plant, q):
    """The 2R arm's tip position in the world at joint positions ``q``."""
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, joint_vector(q, "q", "tip_position", plant))
    return plant.GetFrameByName("tip").CalcPoseInWorld(context).translation()


def point_task(plant, q0):
    """The task: x selected (velocity/position rows E_p = [1 0]), z = z(q0) force-controlled
    (C = z - z_0, E_f = [0 1]) on the PlanarPointChart of the world x-z plane."""
    chart = PlanarPointChart()
    x, z = chart.symbols
    height = float(tip_position(plant, q0)[2])
    constraint = Constraint(chart, [z - height], name="z = z0")
    return ConstraintSpace(constraint, GivenVelocityProjection(chart, [[1, 0]]))


def build_two_link_loop(controller, q0=HINTED_CONFIGURATION, joint_gains=JOINT_GAINS, servo_rate=SERVO_RATE,
                        li_sastry_gains=LI_SASTRY_GAINS):
    """The continuous closed loop of ``controller`` (one of CONTROLLERS) at rest at ``q0``: commands
    zero (no motion, F_d = 0), the measured wrench zero (nothing to push on)."""
    builder = DiagramBuilder()
    plant, _ = two_link_plant(builder)
    q0 = joint_vector(q0, "q0", "build_two_link_loop", plant)
    space = point_task(plant, q0)
    tip = plant.GetFrameByName("tip")
    if controller == "li-sastry":
        system = HybridController(plant, tip, np.zeros(3), space, gains=li_sastry_gains, mode="position-force")
    elif controller == "pd-open-loop-force":
        # Row stiffness and damping K = K_p, D = K_v: Li & Sastry's position-mode design on the free x row.
        system = AxisPDOpenLoopForceController(plant, tip, np.zeros(3), space, gains=li_sastry_gains,
                                               stiffness=li_sastry_gains.position, damping=li_sastry_gains.velocity)
    elif controller in ("raibert-craig", "fisher-mujtaba"):
        system = JointServoHybridController(plant, tip, np.zeros(3), space, gains=li_sastry_gains,
                                            joint_gains=list(joint_gains), servo_rate=servo_rate,
                                            mapping="inverse" if controller == "raibert-craig" else "pseudoinverse")
    else:
        raise ValueError(f"controller must be one of {list(CONTROLLERS)}, got '{controller}'")
    system = builder.AddNamedSystem("controller", system)
    source = builder.AddNamedSystem("desired", ProfileSource(Profile(value=[0.0]), Profile(value=[0.0]), 1, 1))
    wrench = builder.AddNamedSystem("measured_wrench", ConstantVectorSource(np.zeros(6)))
    connect_hybrid_loop(builder, system, state=plant.get_state_output_port(), wrench=wrench.get_output_port(),
                        actuation=plant.get_actuation_input_port(), source=source, owner="build_two_link_loop")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), q0)
    return TwoLinkLoop(diagram=diagram, plant=plant, controller=system, context=context, q0=q0)


def linearized_eigenvalues(loop):
    """Eigenvalues of Drake's Linearize of the loop at its start (an equilibrium), and A."""
    linear = Linearize(loop.diagram, loop.context, equilibrium_check_tolerance=1e-9)
    A = np.asarray(linear.A())
    return np.linalg.eigvals(A), A


def analytic_eigenvalues(controller, q0=HINTED_CONFIGURATION, joint_gains=JOINT_GAINS, servo_rate=SERVO_RATE,
                         li_sastry_gains=LI_SASTRY_GAINS):
    """The loop's eigenvalues from the models: the joint-servo pairs s^2 + K_s s + K_s mu (module
    docstring; the zero-mu pair is (0, -K_s)), or Li & Sastry's designed motion loop (the roots of
    s^2 + K_v s + K_p; its force loop does not act: nothing is pushed on, e_f = 0)."""
    if controller in ("li-sastry", "pd-open-loop-force"):        # the PD: the same design on the free row
        validated = li_sastry_gains.matrices(1, 1, "position-force")
        return predicted_eigenvalues(validated, "position-force").velocity
    plant, _ = two_link_plant()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, joint_vector(q0, "q0", "analytic_eigenvalues", plant))
    space = point_task(plant, q0)
    kinematics = EndEffectorKinematics(plant, plant.GetFrameByName("tip"), np.zeros(3), space.chart)
    task = kinematics.evaluate(context)
    values = space.evaluate(task.configuration, task.velocity)
    mapping = "inverse" if controller == "raibert-craig" else "pseudoinverse"
    _, roots = joint_servo_eigenvalues(task.jacobian, values.velocity_projection, values.matrix, joint_gains,
                                       servo_rate, mapping)
    return roots


def unstable_mode_trajectory(loop, A, duration=3.0, perturbation=1e-8, samples=200):
    """Simulate the loop from its equilibrium plus ``perturbation`` along the right eigenvector of
    A's eigenvalue with the largest real part; returns (times, |w^T (x(t) - x0)|, that eigenvalue)
    with w its left eigenvector: the mode's coordinate, e^(lambda t) |z(0)| while it stays linear."""
    eigenvalues, right = np.linalg.eig(A)
    index = int(np.argmax(eigenvalues.real))
    left = np.linalg.inv(right)[index]
    x0 = loop.context.get_continuous_state_vector().CopyToVector()
    context = loop.context.Clone()
    direction = np.real(right[:, index])
    context.SetContinuousState(x0 + perturbation * direction / np.linalg.norm(direction))
    simulator = Simulator(loop.diagram, context)
    simulator.get_mutable_integrator().set_target_accuracy(1e-10)
    times, coordinates = np.linspace(0.0, duration, samples), []
    for t in times:
        simulator.AdvanceTo(t)
        coordinates.append(abs(left @ (context.get_continuous_state_vector().CopyToVector() - x0)))
    return times, np.array(coordinates), eigenvalues[index]


def simulated_growth_rate(loop, A, duration=3.0, perturbation=1e-8, samples=200):
    """The growth rate (1/s) of the loop's fastest-growing mode in simulation, a least-squares fit
    of log|z(t)| (``unstable_mode_trajectory``) over the second half of the run, and the
    linearization's real part of it: (simulated, linearized)."""
    times, coordinates, eigenvalue = unstable_mode_trajectory(loop, A, duration, perturbation, samples)
    late = times >= duration / 2
    slope = np.polyfit(times[late], np.log(coordinates[late]), 1)[0]
    return float(slope), float(eigenvalue.real)


def stability_map(q1, q2, joint_gains=JOINT_GAINS, servo_rate=SERVO_RATE, singular=1e-3):
    """The largest real part of the joint-servo loop's eigenvalues over a grid of configurations.

    The model is ``control.baselines.joint_servo_eigenvalues`` (the controllers' own T), leaving
    out the zero rate of the unselected direction. Returns {"raibert-craig": R, "fisher-mujtaba": F}
    with R[i, j] at (q1[j], q2[i]) (1/s; NaN
    where |det J| < ``singular``, the arm's singularity). Li & Sastry's design does not depend on
    the configuration (its eigenvalues are those of s^2 + K_v s + K_p wherever J is regular)."""
    plant, _ = two_link_plant()
    context = plant.CreateDefaultContext()
    tip = plant.GetFrameByName("tip")
    chart = PlanarPointChart()
    kinematics = EndEffectorKinematics(plant, tip, np.zeros(3), chart)
    E_p, E = np.array([[1.0, 0.0]]), np.eye(2)            # x selected, z force-controlled (point_task)
    maps = {name: np.full((len(q2), len(q1)), np.nan) for name in ("raibert-craig", "fisher-mujtaba")}
    for i, b in enumerate(q2):
        for j, a in enumerate(q1):
            plant.SetPositions(context, [a, b])
            J = kinematics.evaluate(context).jacobian
            if abs(np.linalg.det(J)) < singular:
                continue
            for name, mapping in (("raibert-craig", "inverse"), ("fisher-mujtaba", "pseudoinverse")):
                mu, roots = joint_servo_eigenvalues(J, E_p, E, joint_gains, servo_rate, mapping)
                nonzero = np.abs(mu) > 1e-12                   # rank-one S: the other mu is 0 (roots 0, -K_s)
                maps[name][i, j] = float(np.max(roots.reshape(-1, 2)[nonzero].real))
    return maps
