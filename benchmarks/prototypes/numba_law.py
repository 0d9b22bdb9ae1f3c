"""Prototype (scratch): the lean law with its numerics compiled by numba (optional, ``pip install numba``).

    python benchmarks/prototypes/numba_law.py [--robots planar-3r ur5e] [--samples 3000]

Per tick the Python side makes only the Drake calls (pose, J_g, bias
acceleration, force elements, inverse dynamics) and TWO compiled calls: the
fused symbolic function (C, E_f, E_f-dot, E_f-dot nu / E_p, E_p-dot nu; the
CSE program of ``symbolic.CompiledFunction`` written into a preallocated
array) and the whole law's linear algebra (kernel E_p, rank margins, E^-1,
wrench split, (3.1-12), J^-1). This estimates the floor of a Python-driven
controller: Drake's systems-framework overhead + the plant calls + two
compiled calls. Float only (the AutoDiffXd path would stay as it is).
"""

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import sympy

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numba  # noqa: E402
from lean_law import LeanLaw, _column, check_agreement, make_solution  # noqa: E402

from drake_hybrid.core.errors import ConstraintRankError  # noqa: E402
from drake_hybrid.core.symbolic import _Printer  # noqa: E402


def compile_into_array(name, argument_symbols, column):
    """numba function f(a, b, out) writing the entries of ``column`` into out (CSE program)."""
    printer = _Printer()
    replacements, reduced = sympy.cse(list(column), symbols=sympy.numbered_symbols("_t"), optimizations="basic")
    lines = [f"def {name}(_arg0, _arg1, _out):"]
    for i, group in enumerate(argument_symbols):
        for j, symbol in enumerate(group):
            lines.append(f"    {printer.doprint(symbol)} = _arg{i}[{j}]")
    for symbol, expression in replacements:
        lines.append(f"    {printer.doprint(symbol)} = {printer.doprint(expression)}")
    for i, expression in enumerate(reduced):
        lines.append(f"    _out[{i}] = {printer.doprint(expression)}")
    scope = {n: getattr(math, n) for n in ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp", "log")}
    scope.update(pi=math.pi, E=math.e)
    exec(compile("\n".join(lines), f"<numba {name}>", "exec"), scope)
    return numba.njit(cache=False, fastmath=False)(scope[name])


@numba.njit(cache=False)
def kernel_projection(E_f, E_f_dot, G, half_lower, nu):
    """(E_p, E_p-dot nu, margin of E_f, margin of G P_N) (KernelVelocityProjection, float)."""
    d = E_f.shape[1]
    A = E_f @ E_f.T
    A_inverse = np.linalg.inv(A)
    pseudo_inverse = E_f.T @ A_inverse
    P_N = np.eye(d) - pseudo_inverse @ E_f
    B = pseudo_inverse @ E_f_dot
    A_dot = E_f_dot @ E_f.T
    A_dot = A_dot + A_dot.T
    P_N_dot = pseudo_inverse @ A_dot @ pseudo_inverse.T - B - B.T
    Y = G @ P_N
    Y_dot = G @ P_N_dot
    S = Y @ Y.T
    L = np.linalg.cholesky(S)
    margin_Y = math.sqrt(np.prod(np.diag(L)) ** 2 / np.prod(np.diag(S)))
    margin_f = math.sqrt(np.linalg.det(A) / np.prod(np.diag(A)))
    L_inverse = np.linalg.inv(L)
    E_p = L_inverse @ Y
    S_dot = Y_dot @ Y.T
    S_dot = S_dot + S_dot.T
    Phi = (L_inverse @ S_dot @ L_inverse.T) * half_lower
    E_p_dot = L_inverse @ (Y_dot - L @ Phi @ E_p)
    return E_p, E_p_dot @ nu, margin_f, margin_Y


@numba.njit(cache=False)
def hybrid_law(E_p, E_p_dot_nu, E_f, curvature, J, bias, nu, w, desired_velocity, desired_acceleration,
               desired_force, xi, e_p, K_v, K_p, K_fp, K_fi, integrates_position, wrench_valid, force_controlled,
               held_acceleration):
    """(joint acceleration, J^T E_f^T u_f, e_p', e_f, r-dot_p, F, F_v, margin of E) of (3.1-12) / Remark 3.
    ``force_controlled``: 1 on force rows, 0 on kinematic rows, whose C-ddot is ``held_acceleration``."""
    k = E_p.shape[0]
    d = E_p.shape[1]
    E = np.empty((d, d))
    E[:k] = E_p
    E[k:] = E_f
    row_norms = np.sqrt((E * E).sum(axis=1))
    margin_E = abs(np.linalg.det(E)) / np.prod(row_norms)
    E_inverse = np.linalg.inv(E)
    if wrench_valid:
        split = E_inverse.T @ w
        tangential_force = split[:k].copy()
        force = split[k:].copy()
    else:
        tangential_force = np.zeros(k)
        force = desired_force.copy()
    force_error = (force - desired_force) * force_controlled
    projected_velocity = E_p @ nu
    velocity_error = projected_velocity - desired_velocity
    acceleration = desired_acceleration - K_v @ velocity_error
    if integrates_position:
        acceleration = acceleration - K_p @ e_p
    rhs = np.empty(d)
    rhs[:k] = acceleration - E_p_dot_nu
    rhs[k:] = -curvature + held_acceleration
    task_acceleration = E_inverse @ rhs
    force_command = K_fi @ xi + K_fp @ force_error - desired_force
    force_torque = J.T @ (E_f.T @ force_command)
    joint_acceleration = np.linalg.solve(J, task_acceleration - bias)
    return (joint_acceleration, force_torque, velocity_error, force_error, projected_velocity, force,
            tangential_force, margin_E)


class NumbaLaw(LeanLaw):
    def _compile(self):
        super()._compile()
        chart = self.chart
        column = _column(*[matrix for _, matrix in self.pieces])
        self.flat = np.empty(len(column))
        self.numba_symbolic = compile_into_array(
            "fused_symbolic", [chart.configuration_symbols, chart.velocity_symbols], column)
        if not self.kernel:
            self.half_lower = np.zeros((1, 1))

    def __call__(self, context, plant_context):
        c = self.controller
        m = self.m
        gains = self.gains
        state = c._state_port.Eval(context)
        plant = self.plant
        x, nu, J, bias = self._kinematics(plant_context, state)
        wrench = c._wrench_port.Eval(context)
        w = self._chart_wrench(wrench)
        flat = self.flat
        self.numba_symbolic(x, nu, flat)
        layout = self.layout
        piece = lambda name: flat[layout[name][0]].reshape(layout[name][1]) if layout[name][1][1] > 1 \
            else flat[layout[name][0]]
        E_f = piece("E_f")
        if self.kernel:
            E_p, E_p_dot_nu, margin_f, margin_Y = kernel_projection(E_f, piece("E_f_dot"), self.projection.basis,
                                                                    self.half_lower, nu)
            if margin_Y < self.projection.rank_tolerance:
                raise ConstraintRankError("kernel E_p lost rank")
        else:
            E_p, E_p_dot_nu = piece("E_p"), piece("E_p_dot_nu")
            margin_f = 1.0 if m == 1 else float(np.sqrt(np.linalg.det(E_f @ E_f.T) / np.prod((E_f * E_f).sum(1))))
        if margin_f < self.constraint.rank_tolerance:
            raise ConstraintRankError("E_f lost rank")
        integrals = c._integrals(context)
        wrench_valid = math.isfinite(wrench.sum())
        held = np.zeros(m)
        if c.kinematic_rows:      # held by the controller: C-ddot = -3 w_c C-dot - 2 w_c^2 C
            w_c = gains.constraint_frequency
            held = (-3.0 * w_c * (E_f @ nu) - 2.0 * w_c * w_c * piece("C")) * (1.0 - c._force_controlled)
        (joint_acceleration, force_torque, velocity_error, force_error, projected_velocity, force, tangential_force,
         margin_E) = hybrid_law(E_p, E_p_dot_nu, E_f, piece("curvature"), J, bias, nu, w,
                                c._velocity_port.Eval(context), c._acceleration_port.Eval(context),
                                c._force_port.Eval(context), integrals[:m], integrals[m:], gains.velocity,
                                gains.position, gains.force_proportional, gains.force_integral,
                                c.mode.integrates_position, wrench_valid, c._force_controlled, held)
        if margin_E < self.space.invertibility_tolerance:
            raise ConstraintRankError("E singular")
        plant.CalcForceElementsContribution(plant_context, self.forces)
        torque = plant.CalcInverseDynamics(plant_context, joint_acceleration, self.forces) + force_torque
        return make_solution(c._actuation_from_torque @ torque, velocity_error, force_error, piece("C").copy(),
                             projected_velocity, force, tangential_force, wrench_valid)


def main(argv=None):
    from robots import make_robot
    from tick import hybrid_evaluation, interleaved, inverse_dynamics_evaluation

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", nargs="+", default=["planar-3r", "ur5e"])
    parser.add_argument("--samples", type=int, default=3000)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    print("| robot | variant | tick us (median) | p95 | IDC us | ratio | max |numba - library| |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for name in args.robots:
        library = make_robot(name)
        lean = make_robot(name)
        lean.controller._evaluate_law = LeanLaw(lean.controller)
        compiled = make_robot(name)
        compiled.controller._evaluate_law = NumbaLaw(compiled.controller)
        error = check_agreement(library, NumbaLaw)
        evaluations = [hybrid_evaluation(r, rng) for r in (library, lean, compiled)]
        evaluations.append(inverse_dynamics_evaluation(library, rng))
        timings = interleaved(evaluations, args.samples, args.samples // 10)
        idc = timings[-1]
        for label, timing, err in zip(("library", "lean numpy", "numba"), timings, (0.0, None, error)):
            print(f"| {name} | {label} | {timing.median_us:.1f} | {timing.p95_us:.1f} | {idc.median_us:.1f} | "
                  f"{timing.median_us / idc.median_us:.1f} | {'-' if err is None else f'{err:.1e}'} |")


if __name__ == "__main__":
    main()
