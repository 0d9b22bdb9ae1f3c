"""Coordinate charts for the end-effector configuration manifold M (paper section 2.1).

A chart fixes two things:

* the **configuration coordinates** x in which the user writes the task
  constraint C(x) = 0 (the paper's r), and
* the **velocity coordinates** nu (size d) in which the controller works: the
  paper's r-dot, or, for the singularity-free chart, the world twist.

The two are related by x-dot = L(x) nu (``configuration_rate``), which is all
the constraint layer needs to differentiate C. Drake's spatial quantities
(``[omega; v]`` ordering, world frame) are mapped to and from nu here:

=============================  =========================================
Drake (world frame)            chart (paper's notation)
=============================  =========================================
V_WE = [omega; v] = J_g q-dot   nu = J q-dot            (analytic Jacobian)
A_bias = J_g-dot q-dot          J-dot q-dot
F_E_W = [n; f] (SpatialForce)   w = B^T F  (generalized force dual to nu)
=============================  =========================================

Charts provided:

``PlanarChart``
    r = (x, y, theta) in a plane (Example 2.1). No singularity.
``PlanarPointChart``
    r = (x, y), a point in a plane without orientation (the 2R arm of ``analysis.kinematic_instability``).
``EulerZXZChart``
    r = (x, y, z, phi, theta, psi) with R = Rz(phi) Rx(theta) Rz(psi)
    exactly as (2.1-2). Singular where sin(theta) = 0 (approach vector along
    +-z): evaluating it there raises ``ChartSingularityError``.
``PoseChart``
    Singularity-free alternative (our answer to the paper's section 4): the
    configuration is the pose itself (p, R: 12 numbers) and the velocity is
    the world twist (v, omega) (quasi-velocities). Trade-off: constraints are
    written in p and the entries of R (or helpers such as the approach vector)
    rather than in angles, and the rotational velocity rows are not
    integrable, so an integrated rotational "position" error is path
    dependent (docs/theory.md §6, position errors).
"""

import math
from typing import Optional, Tuple, Union

import numpy as np
import sympy
from numpy.typing import ArrayLike

import pydrake.math as drake_math
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.core.arguments import number, vector
from drake_hybrid.core.errors import ChartSingularityError, DimensionError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.linalg import is_autodiff, value
from drake_hybrid.core.symbolic import CompiledFunction


def _trig(array):
    """(sin, cos, atan2, acos) suitable for the scalar type of ``array``."""
    if is_autodiff(array):
        return drake_math.sin, drake_math.cos, drake_math.atan2, drake_math.acos
    return math.sin, math.cos, math.atan2, math.acos


def _dtype_of(*arrays):
    return object if is_autodiff(*arrays) else float


class Chart:
    """Base class of coordinate charts. Subclasses define the symbols and maps.

    Attributes (symbolic, sympy):
        configuration_symbols: the coordinates x, in which C(x) is written.
        velocity_symbols: the velocity coordinates nu (size d).
        configuration_rate: x-dot = L(x) nu as a sympy column.
        position: the end-effector point in x (sympy column).
    """

    name = "chart"
    configuration_symbols: Tuple[sympy.Symbol, ...] = ()
    velocity_symbols: Tuple[sympy.Symbol, ...] = ()
    configuration_rate: sympy.Matrix

    @property
    def configuration_size(self) -> int:
        return len(self.configuration_symbols)

    @property
    def velocity_size(self) -> int:
        """d, the dimension of the task (3 planar, 6 spatial)."""
        return len(self.velocity_symbols)

    def configuration_rate_at(self, x: Array, nu: Array) -> Array:
        """x-dot = L(x) nu, numerically (float or AutoDiffXd)."""
        if getattr(self, "_configuration_rate_function", None) is None:
            self._configuration_rate_function = CompiledFunction(
                f"L nu[{self.name}]", [self.configuration_symbols, self.velocity_symbols], self.configuration_rate,
                vector=True)
        return self._configuration_rate_function(x, nu)

    @property
    def symbols(self) -> Tuple[sympy.Symbol, ...]:
        """The configuration symbols, for ``x, y, theta = chart.symbols``."""
        return self.configuration_symbols

    # -- numeric maps, implemented by subclasses --------------------------------
    def configuration(self, R_WE: Array, p_WE: Array) -> Array:
        """Chart coordinates x of the pose (R_WE: 3x3 array, p_WE: 3-vector; float or AutoDiffXd)."""
        raise NotImplementedError

    def configuration_of_pose(self, X_WE: RigidTransform) -> Array:
        """Chart coordinates x of a RigidTransform X_WE."""
        return self.configuration(X_WE.rotation().matrix(), X_WE.translation())

    def pose(self, x: ArrayLike) -> RigidTransform:
        """The pose X_WE (float RigidTransform) with chart coordinates x."""
        raise NotImplementedError

    def check(self, x: Array) -> None:
        """Raise ChartSingularityError if x is at or near the chart's singular set."""

    def singularity_margin(self, x: Array) -> float:
        """Distance-like measure to the chart's singular set (1: far; 0: singular)."""
        return 1.0

    def singularity_explanation(self, x: Array) -> Optional[str]:
        """Why a matrix built in this chart's coordinates may be singular at x (None: not the chart's
        doing). ConstraintSpace adds it to its error when E loses rank."""
        return None

    def task_velocity(self, x: Array, V_WE: Array) -> Array:
        """nu from the spatial velocity V_WE = [omega; v] (6-vector)."""
        raise NotImplementedError

    def task_jacobian(self, x: Array, J_spatial: Array) -> Array:
        """Analytic Jacobian J (d x n) from Drake's J_g (6 x n, rows [omega; v])."""
        raise NotImplementedError

    def task_bias(self, x: Array, nu: Array, A_bias: Array) -> Array:
        """J-dot q-dot (d) from Drake's bias spatial acceleration J_g-dot q-dot (6)."""
        raise NotImplementedError

    def generalized_force(self, x: Array, F_spatial: Array) -> Array:
        """w = B^T F: the covector dual to nu of a spatial force [n; f] (world)."""
        raise NotImplementedError

    def spatial_velocity(self, x: Array, nu: Array) -> Array:
        """V_WE = [omega; v] = B(x) nu."""
        raise NotImplementedError

    def _check_size(self, array, size, what):
        if len(array) != size:
            raise DimensionError(f"{self.name}: {what} must have size {size}, got {len(array)}")


class PlanarChart(Chart):
    """r = (x, y, theta) in a plane of the world (paper Example 2.1).

    The plane passes through ``origin`` and is spanned by the orthonormal
    in-plane axes ``axis_x`` (e1) and ``axis_y`` (e2); its normal is
    n = e1 x e2 and theta is the rotation about n, measured from the
    orientation ``reference_rotation`` (R_0):  R_WE = R_n(theta) R_0.
    The default plane is the vertical world x-z plane (e1 = x_W, e2 = z_W,
    n = -y_W) so that gravity acts along -y of the chart, as in the paper.

    Velocity coordinates: (x-dot, y-dot, theta-dot) = (e1.v, e2.v, n.omega).
    There is no singularity.
    """

    name = "planar"

    def __init__(self, origin: ArrayLike = (0.0, 0.0, 0.0), axis_x: ArrayLike = (1.0, 0.0, 0.0),
                 axis_y: ArrayLike = (0.0, 0.0, 1.0),
                 reference_rotation: Optional[Union[RotationMatrix, Array]] = None) -> None:
        e1 = vector(axis_x, "axis_x", "PlanarChart", 3, error=DimensionError)
        e2 = vector(axis_y, "axis_y", "PlanarChart", 3, error=DimensionError)
        if abs(np.linalg.norm(e1) - 1) > 1e-9 or abs(np.linalg.norm(e2) - 1) > 1e-9 or abs(e1 @ e2) > 1e-9:
            raise DimensionError(f"PlanarChart: axis_x {e1} and axis_y {e2} must be orthonormal")
        self.origin = vector(origin, "origin", "PlanarChart", 3, unit="m")
        self.axis_x, self.axis_y = e1, e2
        self.normal: Array = np.cross(e1, e2)
        self.reference_rotation = RotationMatrix() if reference_rotation is None else RotationMatrix(reference_rotation)
        # The end-effector vector that lies along e1 when theta = 0.
        self._u_E = self.reference_rotation.inverse().multiply(e1)
        x, y, theta = sympy.symbols("x y theta", real=True)
        self.configuration_symbols = (x, y, theta)
        self.velocity_symbols = tuple(sympy.symbols("xdot ydot thetadot", real=True))
        self.configuration_rate = sympy.Matrix(self.velocity_symbols)
        self.position = sympy.Matrix([x, y])
        self.angle = theta
        # Rows of B^T (= B^+ since the columns of B are orthonormal), [omega; v] order.
        self._selector = np.zeros((3, 6))
        self._selector[0, 3:] = e1
        self._selector[1, 3:] = e2
        self._selector[2, :3] = self.normal

    def configuration(self, R_WE: Array, p_WE: Array) -> Array:
        p = p_WE - self.origin
        R = R_WE
        _, _, atan2, _ = _trig(R)
        u_W = R @ self._u_E
        return np.array([self.axis_x @ p, self.axis_y @ p, atan2(self.axis_y @ u_W, self.axis_x @ u_W)],
                        dtype=_dtype_of(R, p))

    def pose(self, x: ArrayLike) -> RigidTransform:
        x = value(x)
        self._check_size(x, 3, "x")
        R = RotationMatrix(AngleAxis(x[2], self.normal)).multiply(self.reference_rotation)
        return RigidTransform(R, self.origin + self.axis_x * x[0] + self.axis_y * x[1])

    def task_velocity(self, x: Array, V_WE: Array) -> Array:
        return self._selector @ V_WE

    def task_jacobian(self, x: Array, J_spatial: Array) -> Array:
        return self._selector @ J_spatial

    def task_bias(self, x: Array, nu: Array, A_bias: Array) -> Array:
        return self._selector @ A_bias

    def generalized_force(self, x: Array, F_spatial: Array) -> Array:
        return self._selector @ F_spatial

    def spatial_velocity(self, x: Array, nu: Array) -> Array:
        return self._selector.T @ nu


class PlanarPointChart(PlanarChart):
    """r = (x, y): the position of a point in a plane of the world, without its orientation (d = 2).

    The chart of a planar two-link arm (``analysis.kinematic_instability``: the kinematic instability of the Raibert-Craig
    controller). The plane and its axes as in PlanarChart; ``pose`` keeps the reference rotation.
    """

    name = "planar_point"

    def __init__(self, origin: ArrayLike = (0.0, 0.0, 0.0), axis_x: ArrayLike = (1.0, 0.0, 0.0),
                 axis_y: ArrayLike = (0.0, 0.0, 1.0)) -> None:
        super().__init__(origin, axis_x, axis_y)
        self.configuration_symbols = self.configuration_symbols[:2]
        self.velocity_symbols = self.velocity_symbols[:2]
        self.configuration_rate = sympy.Matrix(self.velocity_symbols)
        self.angle = None
        self._selector = self._selector[:2]

    def configuration(self, R_WE: Array, p_WE: Array) -> Array:
        p = p_WE - self.origin
        return np.array([self.axis_x @ p, self.axis_y @ p], dtype=_dtype_of(R_WE, p))

    def pose(self, x: ArrayLike) -> RigidTransform:
        x = value(x)
        self._check_size(x, 2, "x")
        return RigidTransform(self.reference_rotation, self.origin + self.axis_x * x[0] + self.axis_y * x[1])


def _euler_zxz_symbolic():
    x, y, z, phi, theta, psi = sympy.symbols("x y z phi theta psi", real=True)
    velocity = sympy.symbols("xdot ydot zdot phidot thetadot psidot", real=True)
    c, s = sympy.cos, sympy.sin
    T = sympy.Matrix([[0, c(phi), s(theta) * s(phi)],
                      [0, s(phi), -s(theta) * c(phi)],
                      [1, 0, c(theta)]])
    T_inverse = sympy.Matrix([[-s(phi) * c(theta) / s(theta), c(phi) * c(theta) / s(theta), 1],
                              [c(phi), s(phi), 0],
                              [s(phi) / s(theta), -c(phi) / s(theta), 0]])
    eta_dot = sympy.Matrix(velocity[3:])
    T_dot_eta_dot = (T.diff(phi) * velocity[3] + T.diff(theta) * velocity[4]) * eta_dot
    Rz = lambda a: sympy.Matrix([[c(a), -s(a), 0], [s(a), c(a), 0], [0, 0, 1]])
    Rx = lambda a: sympy.Matrix([[1, 0, 0], [0, c(a), -s(a)], [0, s(a), c(a)]])
    rotation = Rz(phi) * Rx(theta) * Rz(psi)
    return (x, y, z, phi, theta, psi), velocity, T, T_inverse, T_dot_eta_dot, rotation


class EulerZXZChart(Chart):
    """r = (x, y, z, phi, theta, psi), R = Rz(phi) Rx(theta) Rz(psi) = [n o a] (2.1-2).

    The approach vector is a = (sin(theta) sin(phi), -sin(theta) cos(phi), cos(theta)).
    Euler rates map to the world angular velocity by omega = T(eta) eta-dot
    (docs/theory.md §1), so

    * J = blockdiag(I3, T^-1) J_g   (paper order: translation first),
    * J-dot q-dot = blockdiag(I3, T^-1) (J_g-dot q-dot - [0; T-dot eta-dot]),
    * the wrench (f, n) corresponds to w = [f; T^T n].

    The chart is singular where sin(theta) = 0 (det T = -sin(theta)); every
    evaluation with |sin(theta)| < ``singularity_tolerance`` raises
    ``ChartSingularityError``. theta is taken in (0, pi).
    """

    name = "euler_zxz"
    # Below this |sin(theta)| a singular E = [E_p; E_f] is blamed on the chart (singularity_explanation).
    NEAR_SINGULARITY = 0.1

    def __init__(self, singularity_tolerance: float = 1e-2) -> None:
        self.singularity_tolerance = number(singularity_tolerance, "singularity_tolerance", "EulerZXZChart", low=0.0,
                                            low_inclusive=False, high=1.0, high_inclusive=False)
        (symbols, velocity, T, T_inverse, T_dot_eta_dot, rotation) = _euler_zxz_symbolic()
        self.configuration_symbols = symbols
        self.velocity_symbols = velocity
        self.configuration_rate = sympy.Matrix(velocity)
        self.position = sympy.Matrix(symbols[:3])
        self.rotation = rotation
        self.approach = rotation[:, 2]
        eta = symbols[3:]
        self.rate_matrix = CompiledFunction("T(eta)", [eta], T)
        self.rate_matrix_inverse = CompiledFunction("T(eta)^-1", [eta], T_inverse)
        self.rate_matrix_bias = CompiledFunction("T-dot eta-dot", [eta, velocity[3:]], T_dot_eta_dot, vector=True)

    def check(self, x: Array) -> None:
        margin = self.singularity_margin(x)
        if margin < self.singularity_tolerance:
            raise ChartSingularityError(
                f"z-x-z Euler chart is singular at theta = {float(value(x[4])):.6g} rad "
                f"(|sin(theta)| = {margin:.3g} < tolerance {self.singularity_tolerance:g}): the approach "
                "vector is along +-z, where phi and psi rotate about the same axis. Use PoseChart "
                "(singularity-free) or orient the task away from +-z."
            )

    def singularity_margin(self, x: Array) -> float:
        return abs(math.sin(float(value(x[4]))))

    def singularity_explanation(self, x: Array) -> Optional[str]:
        margin = self.singularity_margin(x)
        if margin >= self.NEAR_SINGULARITY:
            return None
        return (f"the {self.name} chart is near its singularity (margin {margin:.3g}): with z-x-z Euler angles "
                "phi and psi turn about the same axis when the approach vector is along +-z. Use PoseChart "
                "(singularity-free) for tasks that pass there.")

    def configuration(self, R_WE: Array, p_WE: Array) -> Array:
        R, p = R_WE, p_WE
        _, _, atan2, acos = _trig(R)
        cos_theta = R[2, 2]
        theta = acos(cos_theta if is_autodiff(R) else min(1.0, max(-1.0, cos_theta)))
        phi = atan2(R[0, 2], -R[1, 2])
        psi = atan2(R[2, 0], R[2, 1])
        x = np.array([p[0], p[1], p[2], phi, theta, psi], dtype=_dtype_of(R, p))
        self.check(x)
        return x

    def pose(self, x: ArrayLike) -> RigidTransform:
        x = value(x)
        self._check_size(x, 6, "x")
        R = (RotationMatrix.MakeZRotation(x[3]).multiply(RotationMatrix.MakeXRotation(x[4]))
             .multiply(RotationMatrix.MakeZRotation(x[5])))
        p: Array = x[:3]     # Array: pydrake's stubs take no numpy slice (core.hints.Array)
        return RigidTransform(R, p)

    def task_velocity(self, x: Array, V_WE: Array) -> Array:
        self.check(x)
        return np.concatenate([V_WE[3:], self.rate_matrix_inverse(x[3:]) @ V_WE[:3]])

    def task_jacobian(self, x: Array, J_spatial: Array) -> Array:
        self.check(x)
        return np.vstack([J_spatial[3:], self.rate_matrix_inverse(x[3:]) @ J_spatial[:3]])

    def task_bias(self, x: Array, nu: Array, A_bias: Array) -> Array:
        self.check(x)
        angular = A_bias[:3] - self.rate_matrix_bias(x[3:], nu[3:])
        return np.concatenate([A_bias[3:], self.rate_matrix_inverse(x[3:]) @ angular])

    def generalized_force(self, x: Array, F_spatial: Array) -> Array:
        return np.concatenate([F_spatial[3:], self.rate_matrix(x[3:]).T @ F_spatial[:3]])

    def spatial_velocity(self, x: Array, nu: Array) -> Array:
        return np.concatenate([self.rate_matrix(x[3:]) @ nu[3:], nu[:3]])


class PoseChart(Chart):
    """Singularity-free chart: x = (p, R) (12 numbers), nu = (v, omega) world twist.

    Symbols: ``x y z`` for p and ``R00 ... R22`` for the entries of R_WE
    (row-major); ``chart.rotation`` is the 3x3 sympy matrix of them and
    ``chart.approach`` its third column. The configuration rate is
    p-dot = v, R-dot = [omega]x R, so E_f = dC/dx L(x) is the derivative of C
    along the twist: no division by sin(theta) anywhere, and a sphere can be
    polished across its pole.

    Velocity coordinates are quasi-velocities: the rows (omega) are not the
    derivative of any coordinate, so integrated rotational errors are path
    dependent. J = [J_v; J_omega], J-dot q-dot = the bias spatial acceleration,
    and w = [f; n].
    """

    name = "pose"

    def __init__(self) -> None:
        x, y, z = sympy.symbols("x y z", real=True)
        entries = sympy.symbols("R00 R01 R02 R10 R11 R12 R20 R21 R22", real=True)
        velocity = sympy.symbols("vx vy vz wx wy wz", real=True)
        self.configuration_symbols = (x, y, z) + tuple(entries)
        self.velocity_symbols = velocity
        self.position = sympy.Matrix([x, y, z])
        self.rotation = sympy.Matrix(3, 3, entries)
        self.approach = self.rotation[:, 2]
        wx, wy, wz = velocity[3:]
        omega_hat = sympy.Matrix([[0, -wz, wy], [wz, 0, -wx], [-wy, wx, 0]])
        R_dot = omega_hat * self.rotation
        self.configuration_rate = sympy.Matrix(list(velocity[:3]) + list(R_dot))
        self._permutation = np.r_[3:6, 0:3]

    def configuration(self, R_WE: Array, p_WE: Array) -> Array:
        return np.concatenate([p_WE, R_WE.reshape(-1)]).astype(_dtype_of(R_WE, p_WE))

    def pose(self, x: ArrayLike) -> RigidTransform:
        x = value(x)
        self._check_size(x, 12, "x")
        p: Array = x[:3]     # Array: pydrake's stubs take no numpy slice (core.hints.Array)
        return RigidTransform(RotationMatrix(x[3:].reshape(3, 3)), p)

    def task_velocity(self, x: Array, V_WE: Array) -> Array:
        return V_WE[self._permutation]

    def task_jacobian(self, x: Array, J_spatial: Array) -> Array:
        return J_spatial[self._permutation]

    def task_bias(self, x: Array, nu: Array, A_bias: Array) -> Array:
        return A_bias[self._permutation]

    def generalized_force(self, x: Array, F_spatial: Array) -> Array:
        return F_spatial[self._permutation]

    def spatial_velocity(self, x: Array, nu: Array) -> Array:
        return nu[self._permutation]
