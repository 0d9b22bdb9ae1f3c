"""The wrench path's lag on a curved constraint: where it puts the velocity loop's eigenvalues.

The law splits the measured wrench with the current E(x): [F_v; F] = E^-T(x) w (3.0-8), and in
velocity-force and position-force mode cancels F_v (``control.law.tangential_compensation``). On a
curved constraint the contact wrench turns with the configuration, w = w(x), and E^-T(x) w(x) has
F_v = 0 (the frictionless contact of §3.1). A measured wrench that lags, w_w = w / (1 + s T) (a
first-order low-pass of w_w = 1 / T: the sensor's, or the one the continuous linearization adds to
break the algebraic loop), is split with an E(x) that has already turned: with
D = dF_v/dr_p at fixed w (the turn of E^-T along the velocity rows; about -F / rho for a normal
force F on a radius rho), the measured F_v is D r_p s T / (1 + s T) and the cancellation applies
its opposite. Through the constrained mobility S of the velocity rows (the Schur complement of
M_f, ``control.law.impedance_blocks``) the rows close as

    s^2 e + K_v s e (+ K_p e) = -S D (s T / (1 + s T)) e,

about a velocity gain K_v + T S D: D < 0 (the usual case, the normal turning back toward the
surface) makes the rows slower by -T S D, and a position-force pair moves apart. The root at 0 of
velocity-force mode stays. It does not depend on the tessellation (it is the geometry of the
constraint), and it vanishes on a flat surface (D = 0) and as T goes to 0.

``wrench_lag_prediction`` evaluates D by central differences of the split at the linearization
point (the wrench held), S from the controller's plant, and returns the eigenvalues of the loop
above (with the filter's state) that partner the designed ones.
"""

from dataclasses import dataclass

import numpy as np

from drake_hybrid.control.law import impedance_blocks, tangential_compensation

STEP = 1e-6   # m or rad along a velocity row, for the central differences of the split


@dataclass
class WrenchLagPrediction:
    """The designed eigenvalues as the wrench path's lag moves them (module docstring)."""

    lag: float                  # T (s), the wrench path's first-order time constant
    turn: np.ndarray            # D = dF_v/dr_p at fixed w (k x k, N/m on translation rows)
    mobility: np.ndarray        # S, the velocity rows' constrained mobility (k x k)
    loop: np.ndarray            # eigenvalues of lagged_loop_matrix (velocity rows and the filter)
    predicted: np.ndarray = None   # the designed eigenvalues, the velocity loop's moved (set by the analysis)


def _turn_of_split(scenario, plant_context, wrench):
    """(D, S, k): D = dF_v/dr_p of [F_v; F] = E^-T(x) w at fixed ``wrench``, by central differences
    along the velocity rows' motions (J q-dot = E^-1 e_j, the smallest q-dot), and S the rows'
    constrained mobility, at the robot's state in ``plant_context`` (the controller's plant)."""
    controller, space = scenario.controller, scenario.constraint_space
    plant, kinematics = scenario.controller_plant, controller.kinematics
    context = plant.CreateDefaultContext()
    q0 = plant.GetPositions(plant_context)
    plant.SetVelocities(context, np.zeros(plant.num_velocities()))

    def evaluate(q):
        plant.SetPositions(context, q)
        task = kinematics.evaluate(context)
        return task, space.evaluate(task.configuration, task.velocity)

    task, values = evaluate(q0)
    k = space.velocity_size
    E_inverse = np.linalg.inv(np.vstack([values.velocity_projection, values.force_projection]))
    turn = np.zeros((k, k))
    for j in range(k):
        q_dot = np.linalg.lstsq(task.jacobian, E_inverse[:, j], rcond=None)[0]
        sides = []
        for sign in (1.0, -1.0):
            moved, moved_values = evaluate(q0 + sign * STEP * q_dot)
            tangential, _ = space.split_wrench(moved_values,
                                               space.chart.generalized_force(moved.configuration, wrench))
            sides.append(tangential)
        turn[:, j] = (sides[0] - sides[1]) / (2.0 * STEP)
    evaluate(q0)
    mobility_task = task.jacobian @ np.linalg.solve(plant.CalcMassMatrix(context), task.jacobian.T)
    M_f, M_fp, M_p = impedance_blocks(values.velocity_projection, values.force_projection, mobility_task,
                                      controller.kinematic_rows)
    mobility = M_p[:k, :k] - M_fp[:, :k].T @ np.linalg.solve(M_f, M_fp[:, :k]) if M_f.shape[0] else M_p[:k, :k]
    return turn, mobility, k


def lagged_loop_matrix(gains, integrates_position, turn, mobility, lag):
    """A of the velocity rows with the lagged cancellation (module docstring): state [r_p; e'; y_f]
    (r_p the rows' displacement, e' the velocity error, y_f the filtered D r_p),
    e'-dot = -K_v e' (- K_p r_p) - S D r_p + S y_f, y_f-dot = (D r_p - y_f) / T."""
    K_v, K_p = gains.velocity, gains.position
    k = K_v.shape[0]
    Z, I = np.zeros((k, k)), np.eye(k)
    stiffness = mobility @ turn + (K_p if integrates_position else Z)
    return np.block([[Z, I, Z],
                     [-stiffness, -K_v, mobility],
                     [turn / lag, Z, -I / lag]])


def wrench_lag_prediction(scenario, root_context):
    """The ``WrenchLagPrediction`` (``predicted`` unset) at ``root_context`` of a continuous closed
    loop ``scenario`` whose wrench path is a first-order low-pass (``sensor.bandwidth_hz`` > 0);
    None where the law does not cancel F_v (impedance-force mode, or
    ``compensate_tangential_force`` off) or the wrench is not filtered."""
    config, controller = scenario.config, scenario.controller
    k = scenario.constraint_space.velocity_size
    bandwidth = float(config.sensor.bandwidth_hz)
    if tangential_compensation(np.zeros(k), controller.mode, config.compensate_tangential_force) is None:
        return None
    if not bandwidth > 0:
        return None
    lag = 1.0 / (2.0 * np.pi * bandwidth)
    controller_context = controller.GetMyContextFromRoot(root_context)
    wrench = np.array(controller.GetInputPort("measured_wrench").Eval(controller_context), dtype=float)
    robot_context = scenario.controller_plant.CreateDefaultContext()
    scenario.controller_plant.SetPositions(robot_context, scenario.plant.GetPositions(
        scenario.plant.GetMyContextFromRoot(root_context))[:scenario.controller_plant.num_positions()])
    turn, mobility, _ = _turn_of_split(scenario, robot_context, wrench)
    loop = np.linalg.eigvals(lagged_loop_matrix(controller.validated_gains(), controller.mode.integrates_position,
                                                turn, mobility, lag))
    return WrenchLagPrediction(lag=lag, turn=turn, mobility=mobility, loop=loop)
