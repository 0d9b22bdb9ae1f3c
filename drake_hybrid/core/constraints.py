"""Task constraints C(x) = 0 on the end-effector configuration (paper sections 2.2, 3.0).

A ``Constraint`` is built once from C written symbolically in a chart's
coordinates (sympy or pydrake.symbolic). Everything the controller needs is
derived and compiled from it:

* ``value(x)``                  C(x)                                  (m)
* ``force_projection(x)``       E_f = dC/dx L(x)   (= dC/dr for r-charts)  (m x d)
* ``curvature(x, nu)``          E_f-dot nu, the Hessian term of (3.0-8)  (m)
* ``force_projection_rate(x, nu)``  the matrix E_f-dot                  (m x d)

where x-dot = L(x) nu is the chart's configuration rate, so for the paper's
charts (L = I) E_f = dC/dr and (E_f-dot r-dot)_i = r-dot^T (d^2 C_i / dr^2) r-dot.
All of them accept float or AutoDiffXd arrays.

The paper's constraints are provided as functions with real geometry (SI
units): ``window_constraint`` (2.2-1), ``crank_constraint`` (2.2-5),
``sphere_constraint`` (2.2-8, with the equator fix, or the p + a form) and
``surface_constraint`` for any user surface f(p) = 0 with the approach vector
along its normal. ``with_force_rows`` turns held (kinematic) rows into force-controlled ones: a flat
tool's orientation rows, whose force is the moment about the controlled point.

Writing your own::

    chart = EulerZXZChart()
    x, y, z, phi, theta, psi = chart.symbols
    table = Constraint(chart, [z - 0.8, sympy.cos(theta) + 1], name="table")
"""


import copy
from typing import Any, Callable, Iterable, Optional, Protocol, Sequence, Tuple, Union

import numpy as np
import sympy

from drake_hybrid.core.charts import Chart, EulerZXZChart, PlanarChart, PoseChart
from drake_hybrid.core.errors import ArgumentError, BranchError, ConstraintRankError, DimensionError, OffConstraintError
from drake_hybrid.core.hints import Array, VectorLike
from drake_hybrid.core.linalg import rank_margin, value
from drake_hybrid.core.symbolic import CompiledFunction, compiled_time_derivative, to_sympy_matrix


def _format_configuration(chart, x):
    x = value(np.asarray(x))
    return "{" + ", ".join(f"{s}={v:.6g}" for s, v in zip(chart.configuration_symbols, x)) + "}"


class Constraint:
    """C(x) = 0 with m rows on a chart's configuration manifold.

    Args:
        chart: the coordinate chart whose symbols C is written in.
        expressions: m expressions (sympy, pydrake.symbolic, or a mix) in
            ``chart.configuration_symbols``.
        name: used in error messages.
        rank_tolerance: ``check_rank`` raises ConstraintRankError where the
            rows of E_f come closer to linear dependence than this
            (``linalg.rank_margin``: 1 for orthogonal rows, 0 for dependent ones,
            independent of row scaling). Near that limit the control law's
            commands grow like 1 / margin.
        branch: optional scalar expression in the chart symbols that must be
            negative on the intended branch of C = 0 (e.g. p . a < 0: the tool
            points toward the workpiece); ``check_branch`` enforces it.
        branch_description: words for the error message of ``check_branch``.
        kinematic_rows: indices of rows that the environment does not enforce
            (e.g. orientation rows of a point contact); the controller holds
            them itself instead of controlling a force along them.

    Raises:
        UnknownVariableError: C uses variables that are not chart coordinates.
        DimensionError: m is not between 1 and d - 1.
    """

    def __init__(self, chart: Chart, expressions: Union[sympy.Matrix, Sequence[Any]], name: str = "constraint",
                 rank_tolerance: float = 1e-3, branch: Optional[Any] = None,
                 branch_description: str = "the intended branch", kinematic_rows: Iterable[int] = ()) -> None:
        self.chart = chart
        self.name = name
        self.rank_tolerance = float(rank_tolerance)
        C = to_sympy_matrix(expressions, chart.configuration_symbols, what=f"constraint '{name}'")
        if C.cols != 1:
            C = C.reshape(C.rows * C.cols, 1)
        self.expressions = C
        m, d = C.rows, chart.velocity_size
        if not 1 <= m <= d - 1:
            raise DimensionError(
                f"constraint '{name}' has {m} rows; a hybrid task on a {d}-dimensional chart needs 1 <= m <= {d - 1}"
            )
        self.size = m
        x = sympy.Matrix(chart.configuration_symbols)
        nu = sympy.Matrix(chart.velocity_symbols)
        x_dot = chart.configuration_rate
        C_dot = C.jacobian(x) * x_dot                     # dC/dt = E_f nu      (3.0-3)
        E_f = C_dot.jacobian(nu)                          # E_f                 (3.0-2)
        curvature = C_dot.jacobian(x) * x_dot             # E_f-dot nu          (3.0-8)
        self._E_f_symbolic = E_f
        # C, E_f and E_f-dot nu as sympy matrices (for compiled fast paths, control/fast_law.py).
        self.symbolic_terms = (C, E_f, curvature)
        self._value = CompiledFunction(f"C[{name}]", [x], C, vector=True)
        self._force_projection = CompiledFunction(f"E_f[{name}]", [x], E_f)
        self._curvature = CompiledFunction(f"E_f-dot nu[{name}]", [x, nu], curvature, vector=True)
        self._force_projection_rate: Optional[CompiledFunction] = None
        self.kinematic_rows = tuple(sorted(set(int(i) for i in kinematic_rows)))
        if any(not 0 <= i < m for i in self.kinematic_rows):
            raise DimensionError(f"constraint '{name}': kinematic_rows {self.kinematic_rows} out of range 0..{m - 1}")
        self.branch_description = branch_description
        self._branch = None
        if branch is not None:
            expression = to_sympy_matrix([branch], chart.configuration_symbols, what=f"branch of '{name}'")
            self._branch = CompiledFunction(f"branch[{name}]", [x], expression, vector=True)

    def __repr__(self):
        return f"Constraint('{self.name}', m={self.size}, chart={self.chart.name})"

    # -- evaluation -------------------------------------------------------------
    def value(self, x: Array) -> Array:
        """C(x)."""
        return self._value(x)

    def force_projection(self, x: Array) -> Array:
        """E_f(x) = dC/dx L(x), an m x d matrix whose rows span the constrained wrenches."""
        return self._force_projection(x)

    def curvature(self, x: Array, nu: Array) -> Array:
        """E_f-dot nu (3.0-8): the term with E_f r-ddot + E_f-dot r-dot = 0 (3.0-7)."""
        return self._curvature(x, nu)

    def force_projection_rate(self, x: Array, nu: Array) -> Array:
        """The matrix E_f-dot = sum_i dE_f/dx_i x-dot_i (m x d)."""
        if self._force_projection_rate is None:
            self._force_projection_rate = compiled_time_derivative(f"E_f-dot[{self.name}]", self._E_f_symbolic,
                                                                   self.chart)
        return self._force_projection_rate(x, nu)

    # -- checks -----------------------------------------------------------------
    def check_rank(self, x: Array, force_projection: Optional[Array] = None) -> None:
        """Raise ConstraintRankError if E_f(x) has (numerically) lost rank."""
        E_f = self.force_projection(x) if force_projection is None else force_projection
        margin = rank_margin(E_f)
        if margin < self.rank_tolerance:
            raise ConstraintRankError(
                f"constraint '{self.name}' loses rank at {_format_configuration(self.chart, x)}: "
                f"the rank margin of E_f = dC is {margin:.3g} < {self.rank_tolerance:g} "
                f"(rank {np.linalg.matrix_rank(value(E_f))} < m = {self.size}). The constraint description is not "
                "valid here (docs/theory.md §2): use another form of C near this configuration."
            )

    def check_satisfied(self, x: Array, tolerance: float) -> None:
        """Raise OffConstraintError if max |C(x)| exceeds ``tolerance``."""
        residual = value(self.value(x))
        if np.max(np.abs(residual)) > tolerance:
            raise OffConstraintError(
                f"configuration {_format_configuration(self.chart, x)} is not on constraint '{self.name}': "
                f"C = {np.array2string(residual, precision=4)} exceeds tolerance {tolerance:g}"
            )

    def check_branch(self, x: Array) -> None:
        """Raise BranchError if x is on the wrong branch of C = 0 (see ``branch``)."""
        if self._branch is None:
            return
        indicator = float(value(self._branch(x))[0])
        if not indicator < 0:
            raise BranchError(
                f"configuration {_format_configuration(self.chart, x)} is on the wrong branch of constraint "
                f"'{self.name}': {self.branch_description} requires the branch indicator to be negative, "
                f"got {indicator:.4g}"
            )


class SelectingConstraint:
    """A constraint with several equivalent descriptions, chosen by configuration.

    Used for the sphere's equator fix (docs/theory.md §2, Example 2.3): (2.2-8)
    keeps components 1, 2 of p x a, which is valid only where a_3 != 0; near
    the equator one keeps the pair whose dropped component k has the largest
    |a_k|. ``select(x)`` returns the index of the piece to use at x. Every
    evaluation delegates to that piece, so E_f is always full rank where some
    piece is.
    """

    def __init__(self, pieces: Sequence[Constraint], select: Callable[[Array], int], name: str,
                 selector: Optional[sympy.Matrix] = None) -> None:
        sizes = {piece.size for piece in pieces}
        if len(sizes) != 1:
            raise DimensionError(f"SelectingConstraint '{name}': pieces have different sizes {sorted(sizes)}")
        self.pieces = list(pieces)
        self.select = select
        self.name = name
        self.chart = pieces[0].chart
        self.size = pieces[0].size
        self.kinematic_rows = pieces[0].kinematic_rows
        self.rank_tolerance = pieces[0].rank_tolerance
        # Optional sympy column s(x) with select(x) = argmax_i |s_i(x)| (lets control/fast_law.py compile it).
        self.selector = selector

    def __repr__(self):
        return f"SelectingConstraint('{self.name}', m={self.size}, pieces={len(self.pieces)})"

    def piece(self, x: Array) -> Constraint:
        return self.pieces[self.select(x)]

    def value(self, x: Array) -> Array:
        return self.piece(x).value(x)

    def force_projection(self, x: Array) -> Array:
        return self.piece(x).force_projection(x)

    def curvature(self, x: Array, nu: Array) -> Array:
        return self.piece(x).curvature(x, nu)

    def force_projection_rate(self, x: Array, nu: Array) -> Array:
        return self.piece(x).force_projection_rate(x, nu)

    def check_rank(self, x: Array, force_projection: Optional[Array] = None) -> None:
        self.piece(x).check_rank(x, force_projection)

    def check_satisfied(self, x: Array, tolerance: float) -> None:
        self.piece(x).check_satisfied(x, tolerance)

    def check_branch(self, x: Array) -> None:
        self.piece(x).check_branch(x)


class ConstraintLike(Protocol):
    """What every function that takes a constraint uses of it: ``Constraint``, ``SelectingConstraint`` and
    ``core.height_field.HeightFieldConstraint`` have it (a type for type hints)."""

    @property
    def chart(self) -> Chart: ...
    @property
    def name(self) -> str: ...
    @property
    def size(self) -> int: ...
    @property
    def kinematic_rows(self) -> Tuple[int, ...]: ...
    @property
    def rank_tolerance(self) -> float: ...
    def value(self, x: Array) -> Array: ...
    def force_projection(self, x: Array) -> Array: ...
    def curvature(self, x: Array, nu: Array) -> Array: ...
    def force_projection_rate(self, x: Array, nu: Array) -> Array: ...
    def check_rank(self, x: Array, force_projection: Optional[Array] = None) -> None: ...
    def check_satisfied(self, x: Array, tolerance: float) -> None: ...
    def check_branch(self, x: Array) -> None: ...


# ----------------------------------------------------------------------------------------
# The paper's constraints, with real geometry.
# ----------------------------------------------------------------------------------------

def _require_chart(chart, kinds, what):
    if not isinstance(chart, kinds):
        names = ", ".join(k.__name__ for k in (kinds if isinstance(kinds, tuple) else (kinds,)))
        raise TypeError(f"{what} needs a chart of type {names}, got {type(chart).__name__}")


def _spatial_chart(chart, what):
    if not hasattr(chart, "approach"):
        raise TypeError(f"{what} needs a 6-DOF chart (EulerZXZChart or PoseChart), got {type(chart).__name__}")


def window_constraint(chart: PlanarChart, height: float = 1.0, normal: VectorLike = (0.0, 1.0),
                      name: str = "window") -> Constraint:
    """Example 2.1 / (2.2-1): the end-effector point on the line n . (x, y) = height.

    With the default normal (0, 1) this is the paper's C = y - height, E_f = [0 1 0].
    """
    _require_chart(chart, PlanarChart, "window_constraint")
    n = np.asarray(normal, dtype=float)
    if n.shape != (2,) or not np.linalg.norm(n) > 0:
        raise DimensionError(f"window_constraint: normal must be a nonzero 2-vector, got {normal}")
    n = n / np.linalg.norm(n)
    x, y, _ = chart.symbols
    expression = sympy.nsimplify(n[0]) * x + sympy.nsimplify(n[1]) * y - sympy.Float(height)
    return Constraint(chart, [expression], name=name)


def crank_constraint(chart: Union[EulerZXZChart, PoseChart], radius: float = 0.2, height: float = 0.3,
                     center: VectorLike = (0.0, 0.0), form: str = "paper", name: str = "crank") -> Constraint:
    """Example 2.2: the end effector on a horizontal circle (the crank handle's path)
    with its approach vector pointing at the crank's vertical axis (inward branch).

    Args:
        radius, height, center: the circle {(x - cx)^2 + (y - cy)^2 = radius^2, z = height}.
        form: ``"paper"`` is (2.2-5) generalised to this circle:
            (X^2 + Y^2 - radius^2, z - height, cos(theta), X cos(phi) + Y sin(phi)),
            X = x - cx, Y = y - cy (EulerZXZChart only; E_f is the corrected (3.3-2)).
            ``"approach"`` is chart-independent: (X^2 + Y^2 - radius^2, z - height,
            a_z, a_x Y - a_y X) (works with PoseChart). ``"orientation"`` is the
            orientation-fixing form C' of docs/theory.md §2 (z - height, X + radius a_x, Y + radius a_y,
            a_z),
            which selects the inward branch by itself.

    The cross-product forms also admit outward-facing solutions (docs/theory.md §2,
    branch caveat); the constraint's ``check_branch`` rejects them
    (a . (X, Y, 0) must be negative).
    """
    _spatial_chart(chart, "crank_constraint")
    cx, cy = (sympy.Float(c) for c in center)
    x, y, z = chart.position
    X, Y = x - cx, y - cy
    a = chart.approach
    rho, b = sympy.Float(radius), sympy.Float(height)
    if form == "paper":
        _require_chart(chart, EulerZXZChart, "crank_constraint(form='paper')")
        _, _, _, phi, theta, _ = chart.symbols
        rows = [X**2 + Y**2 - rho**2, z - b, sympy.cos(theta), X * sympy.cos(phi) + Y * sympy.sin(phi)]
    elif form == "approach":
        rows = [X**2 + Y**2 - rho**2, z - b, a[2], a[0] * Y - a[1] * X]
    elif form == "orientation":
        rows = [z - b, X + rho * a[0], Y + rho * a[1], a[2]]
    else:
        raise ValueError(f"crank_constraint: unknown form '{form}' (use 'paper', 'approach' or 'orientation')")
    return Constraint(chart, rows, name=name, branch=a[0] * X + a[1] * Y,
                      branch_description="the approach vector pointing toward the crank axis (a . (p - axis) < 0)")


def sphere_constraint(chart: Union[EulerZXZChart, PoseChart], center: VectorLike = (0.0, 0.0, 0.0),
                      radius: float = 0.15, form: str = "approach", dropped_component: Union[int, str] = "auto",
                      name: str = "sphere", kinematic_rows: Optional[Sequence[int]] = None,
                      force_in_newtons: bool = False) -> Union[Constraint, SelectingConstraint]:
    """Example 2.3: the end-effector point on a sphere with the approach vector toward its centre.

    Args:
        center, radius: the sphere (SI units).
        form: ``"approach"`` (default) is C = (p - c) + radius a (m = 3), the
            p + a form of docs/theory.md §2: full rank wherever the chart is valid and it selects
            the inward branch. ``"paper"`` is (2.2-8): (|P|^2 - radius^2 and two
            components of P x a, P = p - c).
        dropped_component: for ``"paper"``: which component k (1, 2, 3) of P x a
            to drop. The paper drops k = 3, valid only where a_3 != 0 (away from
            the equator). ``"auto"`` (the equator fix) drops the k with the largest
            |a_k| at each evaluation, so E_f keeps rank 3 at the equator too.
        kinematic_rows: rows not enforced by a point contact (orientation rows);
            default: none for ``"approach"``, (1, 2) for ``"paper"``.
        force_in_newtons: for ``"paper"``, divide the first row by 2 radius, so
            that its E_f row is the unit normal on N and its force is the
            normal force in N (the paper's row gives F = f / (2 radius)).
    """
    _spatial_chart(chart, "sphere_constraint")
    c = [sympy.Float(v) for v in center]
    p = chart.position
    P = sympy.Matrix([p[i] - c[i] for i in range(3)])
    a = chart.approach
    rho = sympy.Float(radius)
    branch_description = "the approach vector pointing toward the sphere's centre ((p - c) . a < 0)"
    branch = P.dot(a)
    if form == "approach":
        rows = list(P + rho * a)
        return Constraint(chart, rows, name=name, branch=branch, branch_description=branch_description,
                          kinematic_rows=kinematic_rows or ())
    if form != "paper":
        raise ValueError(f"sphere_constraint: unknown form '{form}' (use 'approach' or 'paper')")
    cross = P.cross(a)
    rows_kinematic = (1, 2) if kinematic_rows is None else kinematic_rows

    def piece(dropped):
        kept = [k for k in (1, 2, 3) if k != dropped]
        radial = (P.dot(P) - rho**2) / (2 * rho) if force_in_newtons else P.dot(P) - rho**2
        rows = [radial] + [cross[k - 1] for k in kept]
        return Constraint(chart, rows, name=f"{name} (2.2-8, without component {dropped} of (p-c) x a)",
                          branch=branch, branch_description=branch_description, kinematic_rows=rows_kinematic)

    if dropped_component == "auto":
        approach = CompiledFunction(f"a[{name}]", [chart.configuration_symbols], a, vector=True)
        pieces = [piece(1), piece(2), piece(3)]
        return SelectingConstraint(pieces, lambda x: int(np.argmax(np.abs(value(approach(x))))), name=name,
                                   selector=a)
    if dropped_component not in (1, 2, 3):
        raise ValueError(f"sphere_constraint: dropped_component must be 1, 2, 3 or 'auto', got {dropped_component!r}")
    return piece(dropped_component)


def surface_constraint(chart: Union[PlanarChart, EulerZXZChart, PoseChart], surface: Callable[[sympy.Matrix], Any],
                       name: str = "surface", normal_rows: bool = True) -> Constraint:
    """The end-effector point on a user surface f(p) = 0, approach vector along -grad f.

    Args:
        chart: EulerZXZChart or PoseChart (3-D), or PlanarChart (then f(x, y)).
        surface: a function that takes the chart's position (sympy column) and
            returns the scalar expression f(p), e.g.
            ``lambda p: p[0]**2 / 0.3**2 + p[1]**2 / 0.2**2 + p[2]**2 / 0.1**2 - 1``.
            f < 0 inside the workpiece, so grad f is the outward normal.
        normal_rows: add the orientation rows grad f . o_1 = grad f . o_2 = 0
            (o_1, o_2: the first two columns of R, so a is parallel to grad f);
            these rows have rank 2 wherever grad f != 0, on both charts, with no
            equator problem. They are kinematic rows: a point contact does not
            enforce them, the controller does.

    The inward branch (a . grad f < 0) is checked by ``check_branch``.
    """
    p = chart.position
    f = to_sympy_matrix([surface(p)], chart.configuration_symbols, what=f"surface '{name}'")[0]
    if isinstance(chart, PlanarChart) or not normal_rows:
        return Constraint(chart, [f], name=name)
    gradient = sympy.Matrix([f.diff(s) for s in p])
    R = chart.rotation
    rows = [f, gradient.dot(R[:, 0]), gradient.dot(R[:, 1])]
    return Constraint(chart, rows, name=name, branch=gradient.dot(chart.approach),
                      branch_description="the approach vector pointing into the surface (a . grad f < 0)",
                      kinematic_rows=(1, 2))


def with_force_rows(constraint: ConstraintLike, rows: Optional[Iterable[int]] = None) -> ConstraintLike:
    """A copy of ``constraint`` whose kinematic rows ``rows`` (default: all of them) are force-controlled.

    A constraint's orientation rows (``surface_constraint``'s grad f . o_1, grad f . o_2; the surfaces'
    ``offset_constraint``) are held by the controller for a ball pad, which takes no moment. A flat tool
    does: with them force-controlled, their force F = E^-T w is the moment on the tool about the controlled
    point, about o_2 and -o_1 where a is along -grad f, in N m where |grad f| = 1 (the analytic surfaces'
    rows on their offset surface), and a zero F_d on them turns the tool until the contact's pressure is
    centred under the controlled point. The copy shares the compiled functions; only ``kinematic_rows``
    (and its name) differ. ArgumentError for a row that is not a kinematic row of ``constraint``.
    """
    held = tuple(getattr(constraint, "kinematic_rows", ()))
    if not hasattr(constraint, "force_projection") or not hasattr(constraint, "kinematic_rows"):
        raise ArgumentError(f"with_force_rows: constraint must be a Constraint (core.constraints), got "
                            f"{type(constraint).__name__}")
    chosen = held if rows is None else tuple(rows)
    stray = [row for row in chosen if row not in held]
    if stray:
        raise ArgumentError(f"with_force_rows: rows {stray} are not kinematic rows of constraint "
                            f"'{constraint.name}' (its kinematic rows: {list(held)})")
    kept = tuple(row for row in held if row not in chosen)

    def released(piece):
        twin = copy.copy(piece)
        twin.kinematic_rows = kept
        twin.name = f"{piece.name} (moments)" if chosen else piece.name
        return twin

    twin = released(constraint)
    if isinstance(constraint, SelectingConstraint):
        twin.pieces = [released(piece) for piece in constraint.pieces]
    return twin
