"""Velocity projections E_p and the constraint space E = [E_p; E_f] (paper sections 3.0, 3.3).

The velocity-controlled coordinates are r-dot_p = E_p r-dot (3.0-6), with
E_p of rank d - m and E = [E_p; E_f] invertible. Three ways to get E_p:

``GivenVelocityProjection``
    written by the user as E_p(x), e.g. the paper's (3.3-1), (3.3-6) or
    (3.3-11), or the "true-velocity rows" E_t of docs/theory.md §6 (Option A).
    Its rows need not be orthogonal to E_f.
``KernelVelocityProjection``
    automatic: a smooth orthonormal basis of ker E_f, anchored at a
    configuration x_0 (rows = Gram-Schmidt of G P_N(x), with G the orthonormal
    basis of ker E_f(x_0) and P_N the projector onto ker E_f(x)).

``ConstraintSpace`` combines a constraint with a projection. It always uses
the general inverse E^-1 [a_p; 0] (docs/theory.md §3), never
E_p^T (E_p E_p^T)^-1, so non-orthogonal E_p are handled exactly.
"""

from dataclasses import dataclass
from typing import Any, Optional, Sequence, Tuple, Union

import numpy as np
import sympy
from numpy.typing import ArrayLike

from drake_hybrid.core.charts import Chart, EulerZXZChart, PoseChart
from drake_hybrid.core.constraints import ConstraintLike
from drake_hybrid.core.errors import ChartSingularityError, ConstraintRankError, DimensionError
from drake_hybrid.core.hints import Array, VectorLike
from drake_hybrid.core.linalg import LUFactorization, cholesky, inv, rank_margin_from_cholesky
from drake_hybrid.core.preconditions import check_generic_rank
from drake_hybrid.core.symbolic import CompiledFunction, compiled_time_derivative, to_sympy_matrix


class GivenVelocityProjection:
    """E_p(x) given symbolically in the chart's configuration symbols.

    E_p-dot nu is derived symbolically (x-dot = L(x) nu), like E_f-dot nu.
    """

    def __init__(self, chart: Chart, rows: Union[sympy.Matrix, Sequence[Any]], name: str = "E_p") -> None:
        self.chart = chart
        self.name = name
        E_p = to_sympy_matrix(rows, chart.configuration_symbols, what=f"velocity projection '{name}'")
        d = chart.velocity_size
        if E_p.cols != d:
            raise DimensionError(f"velocity projection '{name}' must have {d} columns (the chart's d), got {E_p.cols}")
        self.size = E_p.rows
        x = sympy.Matrix(chart.configuration_symbols)
        nu = sympy.Matrix(chart.velocity_symbols)
        E_p_nu = E_p * nu
        rate = E_p_nu.jacobian(x) * chart.configuration_rate           # E_p-dot nu   (3.0-9)
        self._matrix = CompiledFunction(f"E_p[{name}]", [x], E_p)
        self._rate = CompiledFunction(f"E_p-dot nu[{name}]", [x, nu], rate, vector=True)
        self._symbolic = E_p
        self.symbolic_terms = (E_p, rate)        # E_p and E_p-dot nu as sympy (control/fast_law.py)
        self._rate_matrix: Optional[CompiledFunction] = None

    def __repr__(self):
        return f"GivenVelocityProjection('{self.name}', rows={self.size})"

    def matrix(self, x: Array) -> Array:
        """E_p(x)."""
        return self._matrix(x)

    def evaluate(self, x: Array, nu: Array, force_projection: Optional[Array] = None,
                 force_projection_rate: Optional[Array] = None) -> Tuple[Array, Array]:
        """(E_p, E_p-dot nu) at (x, nu)."""
        return self._matrix(x), self._rate(x, nu)

    def matrix_and_rate(self, x: Array, nu: Array) -> Tuple[Array, Array]:
        """(E_p, E_p-dot) at (x, nu), E_p-dot = sum_i dE_p/dx_i x-dot_i the matrix."""
        if self._rate_matrix is None:
            self._rate_matrix = compiled_time_derivative(f"E_p-dot[{self.name}]", self._symbolic, self.chart)
        return self._matrix(x), self._rate_matrix(x, nu)


class KernelVelocityProjection:
    """Automatic E_p: a smooth orthonormal basis of ker E_f(x).

    With G the orthonormal basis (rows) of ker E_f(x_0) at the anchor x_0,
    P_N(x) = I - E_f^T (E_f E_f^T)^-1 E_f, Y = G P_N and L L^T = Y Y^T
    (Cholesky), E_p = L^-1 Y. The rows are orthonormal, span ker E_f, equal G
    at the anchor and vary smoothly. E_p-dot follows by differentiating each
    step (using E_f-dot from the constraint). Far from the anchor (where ker
    E_f has turned by about 90 degrees) Y loses rank and ``evaluate`` raises
    ConstraintRankError; anchor the projection nearer the task.
    """

    def __init__(self, constraint: ConstraintLike, anchor: ArrayLike, rank_tolerance: float = 1e-3) -> None:
        self.constraint = constraint
        self.chart = constraint.chart
        self.name = f"ker E_f[{constraint.name}]"
        self.rank_tolerance = float(rank_tolerance)
        anchor = np.asarray(anchor, dtype=float)
        if anchor.shape != (self.chart.configuration_size,):
            raise DimensionError(
                f"KernelVelocityProjection: anchor must have size {self.chart.configuration_size}, got {anchor.shape}")
        E_f0 = constraint.force_projection(anchor)
        constraint.check_rank(anchor, E_f0)
        rows = E_f0.shape[0]
        self.basis = np.linalg.svd(E_f0)[2][rows:]              # G: (d - m) x d
        self.size = self.basis.shape[0]
        d = self.basis.shape[1]
        self._identity = np.eye(d)
        # Phi -> its lower triangle with the diagonal halved, as a product with a constant mask.
        self._half_lower = np.tril(np.ones((self.size, self.size))) - 0.5 * np.eye(self.size)

    def __repr__(self):
        return f"KernelVelocityProjection('{self.name}', rows={self.size})"

    def matrix(self, x: Array) -> Array:
        return self.evaluate(x, np.zeros(self.chart.velocity_size))[0]

    def evaluate(self, x: Array, nu: Array, force_projection: Optional[Array] = None,
                 force_projection_rate: Optional[Array] = None) -> Tuple[Array, Array]:
        """(E_p, E_p-dot nu) at (x, nu)."""
        E_p, E_p_dot = self.matrix_and_rate(x, nu, force_projection, force_projection_rate)
        return E_p, E_p_dot @ nu

    def matrix_and_rate(self, x: Array, nu: Array, force_projection: Optional[Array] = None,
                        force_projection_rate: Optional[Array] = None) -> Tuple[Array, Array]:
        """(E_p, E_p-dot) at (x, nu); E_f and E_f-dot may be passed in when already evaluated."""
        E_f = self.constraint.force_projection(x) if force_projection is None else force_projection
        E_f_dot = (self.constraint.force_projection_rate(x, nu) if force_projection_rate is None
                   else force_projection_rate)
        G = self.basis
        A_inverse = inv(E_f @ E_f.T)
        pseudo_inverse = E_f.T @ A_inverse                       # E_f^+
        P_N = self._identity - pseudo_inverse @ E_f
        # P_N-dot = E_f^+ A-dot E_f^+T - B - B^T, with A-dot = E_f-dot E_f^T + E_f E_f-dot^T, B = E_f^+ E_f-dot
        B = pseudo_inverse @ E_f_dot
        A_dot = E_f_dot @ E_f.T
        A_dot = A_dot + A_dot.T
        P_N_dot = pseudo_inverse @ A_dot @ pseudo_inverse.T - B - B.T
        Y = G @ P_N
        Y_dot = G @ P_N_dot
        S = Y @ Y.T
        try:
            L = cholesky(S)
            margin = rank_margin_from_cholesky(L, S.diagonal())   # = rank_margin(Y): det S = prod(diag L)^2
        except np.linalg.LinAlgError:
            margin = 0.0
        if margin < self.rank_tolerance:
            raise ConstraintRankError(
                f"automatic velocity projection of '{self.constraint.name}' lost rank (margin {margin:.3g}) "
                "far from its anchor: ker E_f has turned too far; re-anchor the KernelVelocityProjection")
        L_inverse = inv(L)
        E_p = L_inverse @ Y
        S_dot = Y_dot @ Y.T
        S_dot = S_dot + S_dot.T
        Phi = (L_inverse @ S_dot @ L_inverse.T) * self._half_lower  # lower triangle, half diagonal
        L_dot = L @ Phi
        E_p_dot = L_inverse @ (Y_dot - L_dot @ E_p)
        return E_p, E_p_dot


@dataclass
class ConstraintSpaceValues:
    """E and its pieces at one (x, nu)."""

    constraint_value: Array          # C(x)                   (m)
    force_projection: Array          # E_f                    (m x d)
    velocity_projection: Array       # E_p                    (d-m x d)
    force_curvature: Array           # E_f-dot nu             (m)
    velocity_curvature: Array        # E_p-dot nu             (d-m)
    matrix: Array                    # E = [E_p; E_f]         (d x d)
    factorization: LUFactorization   # E factored once for E^-1 and E^-T


# A velocity projection of either kind: ConstraintSpace takes both.
AnyVelocityProjection = Union[GivenVelocityProjection, KernelVelocityProjection]


class ConstraintSpace:
    """The constraint space of (3.0-x): E = [E_p; E_f] and the maps built on it.

    Args:
        constraint: a Constraint (or SelectingConstraint).
        velocity_projection: GivenVelocityProjection or KernelVelocityProjection
            with d - m rows.
        invertibility_tolerance: ``evaluate`` raises ConstraintRankError when
            the rank margin of E (see ``linalg.rank_margin``) is below it.
    """

    def __init__(self, constraint: ConstraintLike, velocity_projection: AnyVelocityProjection,
                 invertibility_tolerance: float = 1e-3) -> None:
        chart = constraint.chart
        d, m = chart.velocity_size, constraint.size
        if velocity_projection.size != d - m:
            raise DimensionError(
                f"velocity projection '{velocity_projection.name}' has {velocity_projection.size} rows; "
                f"constraint '{constraint.name}' has m = {m} rows on a d = {d} chart, so E_p needs d - m = {d - m}")
        if velocity_projection.chart is not chart:
            raise ValueError("the velocity projection and the constraint must use the same chart object")
        self.constraint = constraint
        self.velocity_projection = velocity_projection
        self.chart = chart
        self.force_size = m
        self.velocity_size = d - m
        self.invertibility_tolerance = float(invertibility_tolerance)
        check_generic_rank(self)          # rows dependent everywhere (e.g. two identical rows): refused now

    def evaluate(self, x: Array, nu: Array, check: bool = True) -> ConstraintSpaceValues:
        """All of E's pieces at (x, nu); checks the chart, rank E_f and invertibility of E."""
        if check:
            self.chart.check(x)
        constraint = self.constraint
        E_f = constraint.force_projection(x)
        if check:
            constraint.check_rank(x, E_f)
        E_f_dot = None
        if isinstance(self.velocity_projection, KernelVelocityProjection):
            E_f_dot = constraint.force_projection_rate(x, nu)
        E_p, E_p_dot_nu = self.velocity_projection.evaluate(x, nu, E_f, E_f_dot)
        E = np.vstack([E_p, E_f])
        factorization = LUFactorization(E)
        if check:
            margin = factorization.rank_margin()
            explanation = self.chart.singularity_explanation(x) if margin < self.invertibility_tolerance else None
            if explanation is not None:
                raise ChartSingularityError(
                    f"E = [E_p; E_f] is singular (rank margin {margin:.3g}) because {explanation}")
            if margin < self.invertibility_tolerance:
                raise ConstraintRankError(
                    f"E = [E_p; E_f] is singular (rank margin {margin:.3g}) for constraint '{constraint.name}' and "
                    f"velocity projection '{self.velocity_projection.name}': E_p must be one-to-one on "
                    "ker E_f (docs/theory.md §3)")
        return ConstraintSpaceValues(
            constraint_value=constraint.value(x),
            force_projection=E_f,
            velocity_projection=E_p,
            force_curvature=constraint.curvature(x, nu),
            velocity_curvature=E_p_dot_nu,
            matrix=E,
            factorization=factorization,
        )

    def task_acceleration(self, values: ConstraintSpaceValues, velocity_acceleration: Array,
                          constraint_acceleration: Optional[Array] = None) -> Array:
        """r-ddot* = E^-1 ([a_p; a_f] - E-dot nu) (3.0-11, docs/theory.md §4).

        Satisfies E_p r-ddot* + E_p-dot nu = a_p and E_f r-ddot* + E_f-dot nu = a_f,
        with a_f = 0 (the paper) unless ``constraint_acceleration`` is given (the
        stabilization of kinematic rows, see HybridController).
        """
        force_rows = -values.force_curvature
        if constraint_acceleration is not None:
            force_rows = force_rows + constraint_acceleration
        rhs = np.concatenate([velocity_acceleration - values.velocity_curvature, force_rows])
        return values.factorization.solve(rhs)

    def split_wrench(self, values: ConstraintSpaceValues, generalized_force: Array) -> Tuple[Array, Array]:
        """(F_v, F) with w = E_p^T F_v + E_f^T F, i.e. [F_v; F] = E^-T w.

        ``generalized_force`` is the chart covector w of the wrench on the
        robot by the environment (sign convention of docs/theory.md §0). F is in
        the coordinates of this E_f: rescaling a row of C rescales F inversely.
        """
        split = values.factorization.solve_transpose(generalized_force)
        k = self.velocity_size
        return split[:k], split[k:]


# ------------------------------------------------------------------------------------------------
# The paper's velocity projections (section 3.3) and the true-velocity rows of docs/theory.md §6.
# ------------------------------------------------------------------------------------------------

def crank_paper_projection(chart: Chart, center: VectorLike = (0.0, 0.0)) -> GivenVelocityProjection:
    """(3.3-6): E_p = [[0 0 0 0 0 1], [-Y X 0 1 0 0]] (X = x - c_x, Y = y - c_y), EulerZXZChart.

    Orthogonal to the (2.2-5) E_f identically. Its second row mixes units: on
    the circle of radius rho it reads (rho^2 + 1) times the crank rate, the
    paper's pseudo-velocity (docs/theory.md §6).
    """
    x, y = chart.symbols[:2]
    X, Y = x - sympy.Float(center[0]), y - sympy.Float(center[1])
    return GivenVelocityProjection(chart, [[0, 0, 0, 0, 0, 1], [-Y, X, 0, 1, 0, 0]], name="E_p crank (3.3-6)")


def crank_true_velocity_projection(chart: Chart, center: VectorLike = (0.0, 0.0),
                                   radius: float = 1.0) -> GivenVelocityProjection:
    """Option A rows E_t for the crank: (psi-dot, crank angle rate alpha-dot) (docs/theory.md §6).

    Row 2 is (-Y x-dot + X y-dot) / radius^2, which is alpha-dot in rad/s on the
    circle. Not orthogonal to E_f: ConstraintSpace uses the general E^-1 block.
    """
    x, y = chart.symbols[:2]
    X, Y = x - sympy.Float(center[0]), y - sympy.Float(center[1])
    rho2 = sympy.Float(radius) ** 2
    return GivenVelocityProjection(chart, [[0, 0, 0, 0, 0, 1], [-Y / rho2, X / rho2, 0, 0, 0, 0]],
                                   name="E_t crank (Option A)")


def _sphere_tangents(chart, center, radius, axis=(0.0, 0.0, 1.0)):
    p = chart.position
    P_hat = sympy.Matrix([(p[i] - sympy.Float(center[i])) / sympy.Float(radius) for i in range(3)])
    t1 = sympy.Matrix([sympy.nsimplify(c) for c in axis]).cross(P_hat)   # e x P: along the circles about e
    t2 = t1.cross(P_hat)                                # with e = e_z: t2 . p-dot = -z-dot on the sphere
    return P_hat, t1, t2


def sphere_paper_projection(chart: EulerZXZChart, center: VectorLike = (0.0, 0.0, 0.0),
                            radius: float = 1.0) -> GivenVelocityProjection:
    """(3.3-11) with the corrected (3.3-13a): rows e_1 = psi-dot and e_i = (t_i, beta_i, 0),
    beta_i = -A^-1 B t_i with A, B the (phi, theta) and p blocks of rows 2-3 of the (2.2-8) E_f
    (EulerZXZChart; singular where det A = -sin(theta) cos(theta) = 0: poles and equator).
    """
    if not isinstance(chart, EulerZXZChart):
        raise TypeError(f"sphere_paper_projection needs an EulerZXZChart, got {type(chart).__name__}")
    x, y, z, phi, theta, psi = chart.symbols
    p = chart.position
    P = sympy.Matrix([p[i] - sympy.Float(center[i]) for i in range(3)])
    cross = P.cross(chart.approach)
    rows_2_3 = sympy.Matrix([cross[0], cross[1]]).jacobian([x, y, z, phi, theta])
    B, A = rows_2_3[:, :3], rows_2_3[:, 3:5]
    A_inverse = sympy.Matrix([[A[1, 1], -A[0, 1]], [-A[1, 0], A[0, 0]]]) / (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0])
    _, t1, t2 = _sphere_tangents(chart, center, radius)
    rows = [[0, 0, 0, 0, 0, 1]]
    for t in (t1, t2):
        beta = -A_inverse * (B * t)
        rows.append(list(t) + list(beta) + [0])
    return GivenVelocityProjection(chart, rows, name="E_p sphere (3.3-11)")


def sphere_true_velocity_projection(chart: Union[EulerZXZChart, PoseChart], center: VectorLike = (0.0, 0.0, 0.0),
                                    radius: float = 1.0, axis: VectorLike = (0.0, 0.0, 1.0)
                                    ) -> GivenVelocityProjection:
    """Option A rows E_t for the sphere: the spin about the approach axis and the tool-point
    velocity along t_1 = e x P-hat and t_2 = t_1 x P-hat, e = ``axis`` (docs/theory.md §6 uses
    e = e_z; m/s on the sphere, times |t_1| = sin of the angle between P-hat and e).

    t_1 and t_2 vanish where P-hat is parallel to e (the poles of e): E = [E_t; E_f] is singular
    there whatever the chart. To cross the z-pole choose another axis (e.g. e_y for a path in the
    x-z plane). The spin row is psi-dot on the EulerZXZChart (as in the paper) and omega . a on
    the PoseChart.
    """
    _, t1, t2 = _sphere_tangents(chart, center, radius, axis)
    if isinstance(chart, EulerZXZChart):
        spin = [0, 0, 0, 0, 0, 1]
    else:
        spin = [0, 0, 0] + list(chart.approach)
    return GivenVelocityProjection(chart, [spin, list(t1) + [0, 0, 0], list(t2) + [0, 0, 0]],
                                   name="E_t sphere (Option A)")


def pseudo_desired_velocity(paper_rows: Array, true_rows: Array, true_desired_velocity: Array,
                            velocity: Array) -> Array:
    """The paper's desired pseudo-velocity (3.3-8), (3.3-16), corrected:
    r-dot_pd = r-dot_td + (E_p - E_t) r-dot, which mixes the command with the measured r-dot."""
    return true_desired_velocity + (paper_rows - true_rows) @ velocity
