"""A smooth height field z = H(X, Y) and the pad's constraint on it, exact to the second derivative.

``HeightField`` is a quintic spline through a grid (scipy's ``RectBivariateSpline``, degree 5: its
derivatives up to the fourth are continuous) in a frame M placed in the world at ``X_WM``.
``HeightFieldConstraint`` is the constraint of a point held on z = H(X, Y) (a ball pad's centre on its
rolling offset, ``core.height_map.HeightMapSurface.offset_constraint``), on the PoseChart::

    C = (f, grad g . o_1, grad g . o_2),   g = Z - H(X, Y),   s = sqrt(1 + H_X^2 + H_Y^2)
    f = f_1 - (kappa / 2) f_1^2 / (1 + (f_1 / REACH)^2),   f_1 = g / s,
    kappa = (H_X^2 H_XX + 2 H_X H_Y H_XY + H_Y^2 H_YY) / s^3

in the map's coordinates (X, Y, Z) = R_MW (p - p_WM). f_1 is the signed distance from the surface to
first order; f adds the second: within ``REACH`` of the surface f is the signed distance to
O(f_1^3), so grad f is the unit normal at the nearest surface point to O(f_1^2), and F_1 reads the
normal force in N where the pad is pressed in too (on a 3 cm bump's flank, 0.8 mm in: 0.005 % from
it, where f_1 alone read 0.2 %); farther out the correction levels off (its gradient stays near
grad f_1, so a start far above the part approaches along the normal). Rows 2, 3 hold a along -grad g
(kinematic rows). C, E_f = dC/dx L(x), E_f-dot nu and the matrix E_f-dot are derived symbolically
once, as ``core.constraints.Constraint`` derives them, with the derivatives of H as symbols h_ij and
the chain rule through X(p), Y(p) written out (d h_ij / dp = h_(i+1)j dX/dp + h_i(j+1) dY/dp), and
compiled (``core.symbolic.CompiledFunction``). Each evaluation reads the spline's derivatives at
(X, Y): E_f-dot nu needs them to the fourth order; with AutoDiffXd input they become AutoDiffXd
scalars whose gradients come from the next order (the fifth: the quintic's piecewise-constant fifth
derivative, which enters only with the factor f_1^2), so Drake's ``Linearize`` differentiates the
constraint exactly.
"""

import numpy as np
import sympy
from scipy.interpolate import RectBivariateSpline

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import BranchError, ConstraintRankError, OffConstraintError
from drake_hybrid.core.linalg import is_autodiff, rank_margin, value
from drake_hybrid.core.symbolic import CompiledFunction

DEGREE = 5                        # the splines' degree: derivatives up to the fourth continuous
JET_ORDER = 4                     # derivatives of H the compiled terms use (E_f-dot nu: fourth)
REACH = 0.02                      # m: how far from the surface the second-order term of the distance acts fully
JETS = [(i, n - i) for n in range(JET_ORDER + 1) for i in range(n, -1, -1)]   # (d/dX order, d/dY order)


class HeightField:
    """A smooth height field z = H(X, Y) in the map's frame: the spline and its derivatives."""

    def __init__(self, x, y, heights, X_WM, name):
        self.spline = RectBivariateSpline(x, y, np.asarray(heights).T, kx=DEGREE, ky=DEGREE, s=0)
        self.bounds = (float(x[0]), float(x[-1]), float(y[0]), float(y[-1]))
        self.X_WM = X_WM
        self.R_MW = X_WM.rotation().inverse().matrix()
        self.p_WM = X_WM.translation()
        self.name = name
        self._last = (None, None)

    def __call__(self, X, Y, dx=0, dy=0):
        """H's (dx, dy) derivative at map coordinates (floats or arrays)."""
        return self.spline.ev(X, Y, dx=dx, dy=dy)

    def derivatives(self, X, Y, order):
        """{(i, j): d^(i+j) H / dX^i dY^j} at a point, i + j <= ``order`` (the last point is cached). An order
        the spline's own evaluation refuses (i or j = DEGREE: the piecewise-constant top derivative) is the
        central difference of the one below it."""
        key = (float(X), float(Y), order)
        if self._last[0] != key:
            self._last = (key, {(i, n - i): self._derivative(float(X), float(Y), i, n - i)
                                for n in range(order + 1) for i in range(n, -1, -1)})
        return self._last[1]

    def _derivative(self, X, Y, i, j, step=1e-6):
        if i < DEGREE and j < DEGREE:
            return float(self.spline.ev(X, Y, dx=i, dy=j))
        if i >= DEGREE:
            return (self._derivative(X + step, Y, i - 1, j) - self._derivative(X - step, Y, i - 1, j)) / (2 * step)
        return (self._derivative(X, Y + step, i, j - 1) - self._derivative(X, Y - step, i, j - 1)) / (2 * step)

    def map_point(self, p_W):
        """Map-frame coordinates of world points."""
        return (np.asarray(p_W, dtype=float) - self.p_WM) @ self.R_MW.T

    def world_point(self, p_M):
        return np.asarray(p_M, dtype=float) @ self.R_MW + self.p_WM

    def normal(self, X, Y):
        """The outward (up, +Z) unit normal of z = H at (X, Y), world frame."""
        n = np.array([-self(X, Y, 1, 0), -self(X, Y, 0, 1), 1.0])
        return self.R_MW.T @ (n / np.linalg.norm(n))


# ------------------------------------------------------------------------------------------------
# The constraint
# ------------------------------------------------------------------------------------------------

def _jet_symbols():
    return {key: sympy.Symbol(f"h_{key[0]}{key[1]}", real=True) for key in JETS}


def _higher(jets, key, axis):
    """The jet symbol one derivative further along ``axis`` (0: X, 1: Y), or None past JET_ORDER."""
    next_key = (key[0] + 1, key[1]) if axis == 0 else (key[0], key[1] + 1)
    return jets.get(next_key)


class HeightFieldConstraint:
    """C = (f, grad g . o_1, grad g . o_2) on the PoseChart for a HeightField (module docstring).

    The same interface as ``core.constraints.Constraint`` (value, force_projection, curvature,
    force_projection_rate and the checks), float or AutoDiffXd, so ConstraintSpace, the controller
    and the sources use it unchanged; rows 2, 3 are kinematic. It has no ``symbolic_terms`` in the
    chart's symbols alone, so the controller runs its generic (not the numba-compiled) law."""

    def __init__(self, chart, field, name="height map", rank_tolerance=1e-3):
        if not isinstance(chart, PoseChart):
            raise TypeError(f"HeightFieldConstraint needs a PoseChart, got {type(chart).__name__}")
        self.chart, self.field, self.name = chart, field, name
        self.size, self.kinematic_rows, self.rank_tolerance = 3, (1, 2), float(rank_tolerance)
        self.branch_description = "the approach vector pointing into the part (a . grad f < 0)"
        jets = self.jets = _jet_symbols()
        p, R = chart.position, chart.rotation
        A = sympy.Matrix(field.R_MW.tolist()).applyfunc(sympy.Float)
        o = sympy.Matrix(list(field.p_WM)).applyfunc(sympy.Float)
        X, Y, Z = list(A * (p - o))
        self._map_rows = (X, Y)
        H, H_X, H_Y = jets[(0, 0)], jets[(1, 0)], jets[(0, 1)]
        slope = sympy.sqrt(1 + H_X ** 2 + H_Y ** 2)
        first = (Z - H) / slope                                              # the distance to first order
        kappa = (H_X ** 2 * jets[(2, 0)] + 2 * H_X * H_Y * jets[(1, 1)] + H_Y ** 2 * jets[(0, 2)]) / slope ** 3
        f = first - kappa / 2 * first ** 2 / (1 + (first / sympy.Float(REACH)) ** 2)     # and to second
        gradient = A.T * sympy.Matrix([-H_X, -H_Y, 1])                      # grad of Z - H(X, Y)
        C = sympy.Matrix([f, gradient.dot(R[:, 0]), gradient.dot(R[:, 1])])
        x, nu = chart.configuration_symbols, sympy.Matrix(chart.velocity_symbols)
        x_dot = chart.configuration_rate
        C_dot = self._total_jacobian(C) * x_dot                              # E_f nu     (3.0-3)
        E_f = C_dot.jacobian(nu)                                             # (3.0-2)
        curvature = self._total_jacobian(C_dot) * x_dot                      # E_f-dot nu (3.0-8)
        rate = sympy.zeros(*E_f.shape)                                       # the matrix E_f-dot
        for column, symbol_rate in zip(self._total_jacobian(E_f.reshape(E_f.rows * E_f.cols, 1)).T.tolist(), x_dot):
            if symbol_rate != 0:
                rate += sympy.Matrix(column).reshape(*E_f.shape) * symbol_rate
        jet_list = [jets[key] for key in JETS]
        self._value = CompiledFunction(f"C[{name}]", [x, jet_list], C, vector=True)
        self._force_projection = CompiledFunction(f"E_f[{name}]", [x, jet_list], E_f)
        self._curvature = CompiledFunction(f"E_f-dot nu[{name}]", [x, chart.velocity_symbols, jet_list], curvature,
                                           vector=True)
        self._rate = CompiledFunction(f"E_f-dot[{name}]", [x, chart.velocity_symbols, jet_list], rate)
        self._branch = CompiledFunction(f"branch[{name}]", [x, jet_list], sympy.Matrix([gradient.dot(R[:, 2])]),
                                        vector=True)

    def __repr__(self):
        return f"HeightFieldConstraint('{self.name}', m=3, chart={self.chart.name})"

    def _total_jacobian(self, column):
        """d column / d x with the chain rule through H's derivatives: d h_ij / dp = h_(i+1)j dX/dp + h_i(j+1) dY/dp."""
        X, Y = self._map_rows
        entries = []
        for expression in column:
            row = []
            for symbol in self.chart.configuration_symbols:
                total = expression.diff(symbol)
                dX, dY = X.diff(symbol), Y.diff(symbol)
                if dX != 0 or dY != 0:
                    for key, jet in self.jets.items():
                        if expression.has(jet):
                            higher = [_higher(self.jets, key, axis) for axis in (0, 1)]
                            if (dX != 0 and higher[0] is None) or (dY != 0 and higher[1] is None):
                                raise ValueError(f"{self.name}: a derivative of H beyond order {JET_ORDER} is needed")
                            chain = (higher[0] * dX if dX != 0 else 0) + (higher[1] * dY if dY != 0 else 0)
                            total += expression.diff(jet) * chain
                row.append(total)
            entries.append(row)
        return sympy.Matrix(entries)

    def _jet_values(self, x):
        """H's derivatives up to JET_ORDER at the map point of x; AutoDiffXd (the next order carries the
        gradient) when x is."""
        field = self.field
        p = x[:3]
        p_M = field.R_MW @ (p - field.p_WM) if is_autodiff(p) else field.R_MW @ (value(p) - field.p_WM)
        X, Y = value(p_M[0]), value(p_M[1])
        derivatives = field.derivatives(X, Y, JET_ORDER + (1 if is_autodiff(p) else 0))
        if not is_autodiff(p):
            return np.array([derivatives[key] for key in JETS])
        dX, dY = p_M[0].derivatives(), p_M[1].derivatives()
        return np.array([AutoDiffXd(derivatives[key], derivatives[(key[0] + 1, key[1])] * dX
                                    + derivatives[(key[0], key[1] + 1)] * dY) for key in JETS], dtype=object)

    # -- evaluation (as core.constraints.Constraint) ------------------------------------------------
    def value(self, x):
        return self._value(x, self._jet_values(x))

    def force_projection(self, x):
        return self._force_projection(x, self._jet_values(x))

    def curvature(self, x, nu):
        return self._curvature(x, nu, self._jet_values(x))

    def force_projection_rate(self, x, nu):
        return self._rate(x, nu, self._jet_values(x))

    # -- checks ----------------------------------------------------------------------------------
    def _where(self, x):
        return f"p = {np.round(value(x)[:3], 5).tolist()}"

    def check_rank(self, x, force_projection=None):
        E_f = self.force_projection(x) if force_projection is None else force_projection
        margin = rank_margin(E_f)
        if margin < self.rank_tolerance:
            raise ConstraintRankError(f"constraint '{self.name}' loses rank at {self._where(x)}: the rank margin of "
                                      f"E_f is {margin:.3g} < {self.rank_tolerance:g}")

    def check_satisfied(self, x, tolerance):
        residual = value(self.value(x))
        if np.max(np.abs(residual)) > tolerance:
            raise OffConstraintError(f"configuration {self._where(x)} is not on constraint '{self.name}': C = "
                                     f"{np.array2string(residual, precision=4)} exceeds tolerance {tolerance:g}")

    def check_branch(self, x):
        indicator = float(value(self._branch(x, self._jet_values(x)))[0])
        if not indicator < 0:
            raise BranchError(f"configuration {self._where(x)} is on the wrong branch of constraint '{self.name}': "
                              f"{self.branch_description} requires a negative indicator, got {indicator:.4g}")
