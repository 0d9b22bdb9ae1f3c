"""Prototype (scratch, not library code): the same control law with the overheads of PROFILE.md removed.

    python benchmarks/prototypes/lean_law.py [--robots planar-3r ur5e] [--samples 3000]

``LeanLaw(controller)`` re-implements ``HybridController._evaluate_law`` for
float, n = d, velocity-force and position-force modes, PlanarChart and
PoseChart, given and kernel E_p, and is swapped into a real controller
(``controller._evaluate_law = LeanLaw(controller)``), so the tick is measured
through the same Drake ports and cache entries as the library's. It checks
that every output agrees with the library's to 1e-9 before timing.

Each optimization can be switched off (``--without NAME``) to measure its
share; the names are those of PROFILE.md's ranked list:

* ``fused-symbolic``: C, E_f, E_f-dot (matrix), E_f-dot nu (and a given E_p,
  E_p-dot nu) in ONE generated function (one CSE, one call, one array), called
  without the argument checks of ``CompiledFunction.__call__``.
* ``rank-from-factors``: the three rank margins from what the law factors
  anyway (det(E_f E_f^T) = det A from its inverse's LU, det(Y Y^T) from the
  Cholesky factor, det E from E's inverse) instead of three separate
  ``rank_margin`` calls (each det(A A^T), einsum, sqrt).
* ``raw-lapack``: numpy's LAPACK gufuncs (``numpy.linalg._umath_linalg``)
  instead of the ``np.linalg`` wrappers (type checks, errstate); the inverse
  of E computed once and used for both E^-1 (3.0-11) and E^-T (the wrench split).
* ``lean-kernel``: the kernel E_p with the algebra simplified (P_N-dot from
  B = E_f^+ E_f-dot: -(B + B^T) + E_f^+ A-dot E_f^+T; a constant mask instead
  of np.tril/np.diag).
* ``lean-kinematics``: X_WE.GetAsMatrix34(), v from the state vector, the
  chart maps inlined (no per-call dtype dispatch, no TaskKinematics dataclass).
"""

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import sympy
from numpy.linalg import _umath_linalg

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pydrake.multibody.tree import JacobianWrtVariable  # noqa: E402

from drake_hybrid.control.controller import ControlSolution  # noqa: E402
from drake_hybrid.core.charts import PlanarChart, PoseChart  # noqa: E402
from drake_hybrid.core.errors import ConstraintRankError  # noqa: E402
from drake_hybrid.core.linalg import rank_margin  # noqa: E402
from drake_hybrid.core.projections import KernelVelocityProjection  # noqa: E402
from drake_hybrid.core.symbolic import CompiledFunction, time_derivative  # noqa: E402

OPTIMIZATIONS = ("fused-symbolic", "rank-from-factors", "raw-lapack", "lean-kernel", "lean-kinematics")


def _column(*matrices):
    return sympy.Matrix([entry for matrix in matrices for entry in matrix])


class LeanLaw:
    def __init__(self, controller, without=()):
        self.on = {name: name not in without for name in OPTIMIZATIONS}
        self.controller = c = controller
        space = c.constraint_space
        self.space, self.chart, self.constraint = space, space.chart, space.constraint
        self.projection = space.velocity_projection
        self.kernel = isinstance(self.projection, KernelVelocityProjection)
        if not isinstance(self.chart, (PlanarChart, PoseChart)):
            raise NotImplementedError("prototype: PlanarChart and PoseChart only")
        if c.num_joints != c.task_size or c.mode.value == "impedance-force":
            raise NotImplementedError("prototype: n = d, velocity-force and position-force only")
        self.k, self.m, self.d, self.n = c.velocity_size, c.force_size, c.task_size, c.num_joints
        self.gains = c._gains
        self.plant, self.forces = c.plant(), c._forces
        kin = c.kinematics
        self.frame, self.point, self.world = kin.frame, kin.point_in_frame, self.plant.world_frame()
        self.eye_d = np.eye(self.d)
        k = self.k
        self.half_lower = np.tril(np.ones((k, k))) - 0.5 * np.eye(k)   # Phi -> tril(Phi) - diag(Phi)/2
        self._compile()

    # -- one generated function for every symbolic quantity -------------------------------------
    def _compile(self):
        chart, constraint = self.chart, self.constraint
        x = sympy.Matrix(chart.configuration_symbols)
        nu = sympy.Matrix(chart.velocity_symbols)
        rate = chart.configuration_rate
        C = constraint.expressions
        C_dot = C.jacobian(x) * rate
        E_f = C_dot.jacobian(nu)
        curvature = C_dot.jacobian(x) * rate
        pieces = [("C", C), ("E_f", E_f), ("curvature", curvature)]
        if self.kernel:
            pieces.append(("E_f_dot", time_derivative(E_f, chart.configuration_symbols, rate)))
        else:
            E_p = self.projection._symbolic
            pieces += [("E_p", E_p), ("E_p_dot_nu", (E_p * nu).jacobian(x) * rate)]
        self.pieces = pieces
        self.layout, start = {}, 0
        for name, matrix in pieces:
            self.layout[name] = (slice(start, start + len(matrix)), matrix.shape)
            start += len(matrix)
        fused = CompiledFunction("fused", [chart.configuration_symbols, chart.velocity_symbols],
                                 _column(*[m for _, m in pieces]), vector=True)
        self.fused = fused._float

    def _symbolic(self, x, nu):
        if self.on["fused-symbolic"]:
            flat = self.fused(x, nu)
            out = {}
            for name, (where, shape) in self.layout.items():
                out[name] = flat[where].reshape(shape) if shape[1] > 1 else flat[where]
            return out
        c, p = self.constraint, self.projection
        out = {"C": c.value(x), "E_f": c.force_projection(x), "curvature": c.curvature(x, nu)}
        if self.kernel:
            out["E_f_dot"] = c.force_projection_rate(x, nu)
        else:
            out["E_p"], out["E_p_dot_nu"] = p.evaluate(x, nu)
        return out

    # -- linear algebra --------------------------------------------------------------------------
    def inv(self, A):
        return _umath_linalg.inv(A) if self.on["raw-lapack"] else np.linalg.inv(A)

    def det(self, A):
        return _umath_linalg.det(A) if self.on["raw-lapack"] else np.linalg.det(A)

    def cholesky(self, A):
        return _umath_linalg.cholesky_lo(A) if self.on["raw-lapack"] else np.linalg.cholesky(A)

    def solve(self, A, b):
        return _umath_linalg.solve1(A, b) if self.on["raw-lapack"] else np.linalg.solve(A, b)

    # -- kinematics ------------------------------------------------------------------------------
    def _kinematics(self, plant_context, state):
        plant, frame, point, world = self.plant, self.frame, self.point, self.world
        if not self.on["lean-kinematics"]:
            task = self.controller.kinematics.evaluate(plant_context)
            return task.configuration, task.velocity, task.jacobian, task.bias
        X = plant.CalcRelativeTransform(plant_context, world, frame).GetAsMatrix34()
        R = X[:, :3]
        p = X[:, 3] + R @ point
        J_spatial = plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, frame, point, world, world)
        A_bias = plant.CalcBiasSpatialAcceleration(plant_context, JacobianWrtVariable.kV, frame, point, world,
                                                   world).get_coeffs()
        v = state[self.n:]
        chart = self.chart
        if isinstance(chart, PoseChart):
            x = np.concatenate([p, R.ravel()])
            J = J_spatial[chart._permutation]
            bias = A_bias[chart._permutation]
        else:
            rel = p - chart.origin
            u = R @ chart._u_E
            x = np.array([chart.axis_x @ rel, chart.axis_y @ rel, math.atan2(chart.axis_y @ u, chart.axis_x @ u)])
            J = chart._selector @ J_spatial
            bias = chart._selector @ A_bias
        return x, J @ v, J, bias

    def _chart_wrench(self, wrench):
        """w = B^T F (chart.generalized_force) for the two charts, inlined."""
        if isinstance(self.chart, PoseChart):
            return wrench[self.chart._permutation]
        return self.chart._selector @ wrench

    # -- the kernel E_p (KernelVelocityProjection.matrix_and_rate, float) -----------------------
    def _kernel(self, E_f, E_f_dot, nu):
        G = self.projection.basis
        A = E_f @ E_f.T
        A_inverse = self.inv(A)
        pseudo_inverse = E_f.T @ A_inverse
        if self.on["lean-kernel"]:
            P_N = self.eye_d - pseudo_inverse @ E_f
            B = pseudo_inverse @ E_f_dot
            A_dot = E_f_dot @ E_f.T
            A_dot = A_dot + A_dot.T
            P_N_dot = pseudo_inverse @ A_dot @ pseudo_inverse.T - B - B.T
        else:
            P_N = np.eye(self.d) - pseudo_inverse @ E_f
            A_dot = E_f_dot @ E_f.T + E_f @ E_f_dot.T
            P_N_dot = -(E_f_dot.T @ A_inverse @ E_f + pseudo_inverse @ E_f_dot
                        - pseudo_inverse @ A_dot @ A_inverse @ E_f)
        Y = G @ P_N
        Y_dot = G @ P_N_dot
        S = Y @ Y.T
        L = self.cholesky(S)
        if self.on["rank-from-factors"]:
            margin_Y = float(np.prod(np.diag(L)) ** 2 / np.prod(np.diag(S))) ** 0.5
            margin_f = float(self.det(A) / np.prod(np.diag(A))) ** 0.5
        else:
            margin_Y, margin_f = rank_margin(Y), rank_margin(E_f)
        if margin_Y < self.projection.rank_tolerance:
            raise ConstraintRankError("kernel E_p lost rank")
        L_inverse = self.inv(L)
        E_p = L_inverse @ Y
        S_dot = Y_dot @ Y.T
        S_dot = S_dot + S_dot.T
        Phi = L_inverse @ S_dot @ L_inverse.T
        if self.on["lean-kernel"]:
            Phi = Phi * self.half_lower
        else:
            Phi = np.tril(Phi) - 0.5 * np.diag(np.diag(Phi))
        E_p_dot = L_inverse @ (Y_dot - L @ Phi @ E_p)
        return E_p, E_p_dot @ nu, margin_f

    # -- the law -----------------------------------------------------------------------------------
    def __call__(self, context, plant_context):
        c = self.controller
        k, m = self.k, self.m
        gains = self.gains
        state = c._state_port.Eval(context)
        x, nu, J, bias = self._kinematics(plant_context, state)
        s = self._symbolic(x, nu)
        E_f = s["E_f"]
        if self.kernel:
            E_p, E_p_dot_nu, margin_f = self._kernel(E_f, s["E_f_dot"], nu)
        else:
            E_p, E_p_dot_nu = s["E_p"], s["E_p_dot_nu"]
            margin_f = (math.sqrt(self.det(E_f @ E_f.T) / np.prod(np.einsum("ij,ij->i", E_f, E_f)))
                        if self.on["rank-from-factors"] else rank_margin(E_f))
        if margin_f < self.constraint.rank_tolerance:
            raise ConstraintRankError("E_f lost rank")
        E = np.vstack([E_p, E_f])
        if self.on["raw-lapack"]:
            E_inverse = self.inv(E)
        if self.on["rank-from-factors"]:
            margin_E = abs(self.det(E)) / math.sqrt(np.prod(np.einsum("ij,ij->i", E, E)))
        else:
            margin_E = rank_margin(E)
        if margin_E < self.space.invertibility_tolerance:
            raise ConstraintRankError("E singular")

        integrals = c._integrals(context)
        xi, e_p = integrals[:m], integrals[m:]
        desired_velocity = c._velocity_port.Eval(context)
        desired_acceleration = c._acceleration_port.Eval(context)
        desired_force = c._force_port.Eval(context)
        wrench = c._wrench_port.Eval(context)
        wrench_valid = math.isfinite(wrench.sum())
        if wrench_valid:
            w = self._chart_wrench(wrench)
            split = E_inverse.T @ w if self.on["raw-lapack"] else np.linalg.solve(E.T, w)
            tangential_force, force = split[:k], split[k:]
        else:
            tangential_force, force = np.zeros(k), desired_force
        force_error = (force - desired_force) * c._force_controlled     # 0 on kinematic rows
        projected_velocity = E_p @ nu
        velocity_error = projected_velocity - desired_velocity
        acceleration = desired_acceleration - gains.velocity @ velocity_error
        if c.mode.integrates_position:
            acceleration = acceleration - gains.position @ e_p
        force_rows = -s["curvature"]
        if c.kinematic_rows:      # held by the controller: C-ddot = -3 w_c C-dot - 2 w_c^2 C
            w_c = gains.constraint_frequency
            force_rows = force_rows + (-3.0 * w_c * (E_f @ nu) - 2.0 * w_c * w_c * s["C"]) * (1.0 - c._force_controlled)
        rhs = np.concatenate([acceleration - E_p_dot_nu, force_rows])
        task_acceleration = E_inverse @ rhs if self.on["raw-lapack"] else np.linalg.solve(E, rhs)
        force_command = gains.force_integral @ xi + gains.force_proportional @ force_error - desired_force
        force_torque = J.T @ (E_f.T @ force_command)
        plant = self.plant
        plant.CalcForceElementsContribution(plant_context, self.forces)
        joint_acceleration = self.solve(J, task_acceleration - bias)
        torque = plant.CalcInverseDynamics(plant_context, joint_acceleration, self.forces) + force_torque
        return make_solution(c._actuation_from_torque @ torque, velocity_error, force_error, s["C"],
                             projected_velocity, force, tangential_force, wrench_valid)


def make_solution(actuation, velocity_error, force_error, constraint_value, projected_velocity, force,
                  tangential_force, wrench_valid):
    """The library's ControlSolution (what the controller's output ports read)."""
    solution = ControlSolution()
    solution.actuation = actuation
    solution.velocity_error = velocity_error
    solution.force_error = force_error
    solution.constraint_value = constraint_value
    solution.projected_velocity = projected_velocity
    solution.force = force
    solution.tangential_force = tangential_force
    solution.position_error_rate = velocity_error
    solution.wrench_valid = wrench_valid
    return solution


OUTPUTS = ("actuation", "velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
           "tangential_force")


def check_agreement(robot, make_law):
    """Max |prototype - library| over every output port, at the robot's state and 20 perturbed
    ones; ``make_law(controller)`` builds the prototype law swapped into a second controller."""
    from robots import make_robot
    from tick import fix_inputs

    reference = robot.controller
    lean = make_robot(robot.name, reference.mode.value).controller
    lean._evaluate_law = make_law(lean)
    worst = 0.0
    rng = np.random.default_rng(3)
    for i in range(21):
        state = robot.state + (0 if i == 0 else 1e-2 * rng.standard_normal(robot.state.size))
        values = []
        for controller in (reference, lean):
            context = controller.CreateDefaultContext()
            fix_inputs(controller, context, dict(robot.inputs, estimated_state=state))
            values.append([controller.GetOutputPort(name).Eval(context) for name in OUTPUTS])
        worst = max(worst, max(float(np.max(np.abs(a - b))) for a, b in zip(*values)))
    return worst


def main(argv=None):
    from robots import make_robot
    from tick import hybrid_evaluation, interleaved, inverse_dynamics_evaluation

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", nargs="+", default=["planar-3r", "ur5e"])
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--mode", default="velocity-force")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    print("| robot | variant | tick us (median) | p95 | IDC us | ratio | max |lean - library| |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name in args.robots:
        variants = [("library", None), ("all optimizations", ())]
        variants += [(f"all but {o}", (o,)) for o in OPTIMIZATIONS]
        evaluations, labels, errors = [], [], []
        robot = make_robot(name, args.mode)
        for label, without in variants:
            r = make_robot(name, args.mode)
            if without is not None:
                r.controller._evaluate_law = LeanLaw(r.controller, without)
                errors.append(check_agreement(robot, lambda c, w=without: LeanLaw(c, w)))
            else:
                errors.append(0.0)
            evaluations.append(hybrid_evaluation(r, rng))
            labels.append(label)
        evaluations.append(inverse_dynamics_evaluation(robot, rng))
        timings = interleaved(evaluations, args.samples, args.samples // 10)
        idc = timings[-1]
        for label, timing, error in zip(labels, timings[:-1], errors):
            print(f"| {name} | {label} | {timing.median_us:.1f} | {timing.p95_us:.1f} | {idc.median_us:.1f} | "
                  f"{timing.median_us / idc.median_us:.1f} | {error:.1e} |")


if __name__ == "__main__":
    main()
