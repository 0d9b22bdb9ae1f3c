"""Workpiece surfaces: where a path lies, what the pad's centre is held to, and the view patterns are drawn in.

A ``Surface`` is the face of a workpiece in world coordinates. The controlled point of a ball pad
of radius r is its centre, which stays on the *offset* surface, r along the outward normal; the
task's constraint is that offset surface (``offset_constraint``), and a path given on the
workpiece (waypoints, a coverage pattern) becomes a path of the pad's centre by
``closest_point`` / ``lift`` and the normal::

    surface.offset_constraint(chart, r)   C = (f_r(p), grad f_r . o_1, grad f_r . o_2)      (m = 3)
                                          f_r the signed distance from the offset surface, so
                                          |grad f_r| = 1 wherever the pad is, pressed in or not, and F_1
                                          is the normal force in N; rows 2, 3 (a along -grad f_r) are held
                                          by the controller (kinematic rows), as in ``surface_constraint``
    surface.closest_point(p) -> (q, n)    the nearest surface point and the outward unit normal there
    surface.lift(view, u, v) -> (q, n)    the surface point seen at (u, v) of a ``ViewPlane``
    surface.normal(p)                     the outward unit normal of the offset family through p

A ``ViewPlane`` is the plane a pattern is drawn in (a top view): an origin, in-plane axes u, v and
the viewing normal w = u x v, pointing from the workpiece toward the viewer. ``lift`` follows the
line through (u, v) along -w to the first surface point it meets. ``view_projection`` is the E_p of
a path drawn in a view: the spin about the approach vector and the pad centre's velocity along u
and v (m/s). Its translational rows are exact differentials, u . (p - p_d) and v . (p - p_d), so a
position error measured against a path has no path-dependent part; E = [E_p; E_f] stays invertible
wherever the surface faces the viewer (``check_facing``: within ``MAX_TILT`` of w).

Provided: ``PlaneSurface``, ``SphereSurface``, ``CylinderSurface``; a height map (a scanned part) is
``core.height_map.HeightMapSurface``.

The pad's offset r (``offset``, here and in ``core.paths``) is the ball pad's radius: a finite number
>= 0 (m; 0 holds the surface point itself). A negative offset would put the controlled point inside the
workpiece (on a sphere of radius R, -r < -R even beyond its centre), which no pad does, so it is
refused (``check_offset``). Every argument is checked at the call (``core.arguments``): a bad one is a
one-line ``PathError`` naming it.
"""

import abc
import math
from dataclasses import dataclass
from typing import Optional, Tuple, Union

import numpy as np
import sympy
from numpy.typing import ArrayLike

from drake_hybrid.core.arguments import instance, nonnegative, number, numeric_array, positive, text, vector
from drake_hybrid.core.charts import Chart, EulerZXZChart, PoseChart
from drake_hybrid.core.constraints import ConstraintLike, surface_constraint
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.hints import Array, VectorLike
from drake_hybrid.core.projections import GivenVelocityProjection

MAX_TILT = 60.0         # deg: the largest angle between the surface normal and a view's w on a path


def _vector(values, what, owner, size=3):
    return vector(values, what, owner, size, error=PathError)


def _unit(values, what, owner):
    direction = _vector(values, what, owner)
    norm = float(np.linalg.norm(direction))
    if not norm > 1e-12:
        raise PathError(f"{owner}: {what} must be a nonzero vector, got {direction.tolist()}")
    return direction / norm


def check_chart(chart: Chart, owner: str) -> Union[PoseChart, EulerZXZChart]:
    """``chart`` if it is a 3-D end-effector chart (PoseChart or EulerZXZChart), else a PathError."""
    return instance(chart, "chart", owner, (PoseChart, EulerZXZChart), what="a PoseChart or an EulerZXZChart",
                    error=PathError)


def check_offset(offset: float, owner: str, name: str = "offset") -> float:
    """The pad's offset as a float: a finite number >= 0 (m; module docstring), else a PathError."""
    return nonnegative(offset, name, owner, unit="m, the pad's radius", error=PathError)


def check_point(p: ArrayLike, owner: str, name: str = "p") -> Array:
    """A world point as a float vector of 3 finite numbers (m), else a PathError."""
    return vector(p, name, owner, 3, unit="m", error=PathError)


def check_view(view: "ViewPlane", owner: str, name: str = "view") -> "ViewPlane":
    """``view`` if it is a ViewPlane, else a PathError."""
    return instance(view, name, owner, ViewPlane, what="a ViewPlane (ViewPlane.make)", error=PathError)


@dataclass(frozen=True)
class ViewPlane:
    """The plane a pattern is drawn in: ``origin`` and orthonormal in-plane axes ``axis_u``, ``axis_v``;
    ``normal`` = u x v points toward the viewer. Make one with ``ViewPlane.make`` (checks, orthonormalizes)."""

    origin: tuple
    axis_u: tuple
    axis_v: tuple

    @staticmethod
    def make(origin: VectorLike = (0.0, 0.0, 0.0), axis_u: VectorLike = (1.0, 0.0, 0.0),
             axis_v: VectorLike = (0.0, 1.0, 0.0), what: str = "view") -> "ViewPlane":
        """A ViewPlane with ``axis_v`` made orthogonal to ``axis_u`` (Gram-Schmidt); PathError naming
        ``what`` for parallel or non-finite axes."""
        owner = "ViewPlane.make"
        o = _vector(origin, f"{text(what, 'what', owner)}.origin", owner)
        u = _unit(axis_u, f"{what}.axis_u", owner)
        v = _vector(axis_v, f"{what}.axis_v", owner)
        v = v - (v @ u) * u
        if not np.linalg.norm(v) > 1e-9:
            raise PathError(f"{what}.axis_v must not be parallel to axis_u, got {list(axis_v)} and {list(axis_u)}")
        return ViewPlane(tuple(o), tuple(u), tuple(v / np.linalg.norm(v)))

    @property
    def normal(self) -> Array:
        """w = u x v, toward the viewer."""
        return np.cross(self.axis_u, self.axis_v)

    def point(self, u: float, v: float) -> Array:
        """The world point at (u, v) of the plane."""
        u, v = (number(x, name, "ViewPlane.point", unit="m", error=PathError) for x, name in ((u, "u"), (v, "v")))
        return np.asarray(self.origin) + u * np.asarray(self.axis_u) + v * np.asarray(self.axis_v)

    def coordinates(self, points: ArrayLike) -> Array:
        """(u, v) of world points (N x 3 or 3) projected onto the plane along w."""
        allowed = "a world point [x, y, z] or N x 3 world points (m)"
        array = numeric_array(points, "points", "ViewPlane.coordinates", what=allowed, error=PathError)
        if array.ndim not in (1, 2) or array.shape[-1] != 3:
            raise PathError(f"ViewPlane.coordinates: points must be {allowed}, got an array of shape {list(array.shape)}")
        d = array - np.asarray(self.origin)
        return np.stack([d @ np.asarray(self.axis_u), d @ np.asarray(self.axis_v)], axis=-1)


def check_facing(normal: ArrayLike, view: ViewPlane, where: str, max_tilt: float = MAX_TILT) -> None:
    """PathError if the surface normal at ``where`` turns more than ``max_tilt`` degrees from the view's
    w: the view's rows of E_p would lose rank against E_f there (and the surface would hide itself)."""
    if not np.all(np.isfinite(normal)):
        raise PathError(f"{where}: the surface normal there is not finite, got {np.asarray(normal).tolist()}")
    cosine = float(np.clip(np.asarray(normal) @ view.normal, -1.0, 1.0))
    tilt = math.degrees(math.acos(cosine))
    if tilt > max_tilt:
        raise PathError(f"{where}: the surface there faces {tilt:.1f} deg away from the view's normal "
                        f"{np.round(view.normal, 3).tolist()} (at most {max_tilt:g} deg): the view's velocity rows "
                        "lose rank there; keep the path where the surface faces the view")


def view_projection(chart: Union[PoseChart, EulerZXZChart], view: ViewPlane,
                    name: str = "E_p (view)") -> GivenVelocityProjection:
    """E_p of a path drawn in ``view``: rows (spin about a, u . p-dot, v . p-dot).

    The spin row is omega . a on the PoseChart, psi-dot on the EulerZXZChart. The other two are the
    pad centre's velocity along the view's axes (m/s); their position errors u . (p - p_d),
    v . (p - p_d) are exact. E = [E_p; E_f] is invertible where the surface's normal has a component
    along w (``check_facing``)."""
    if isinstance(chart, PoseChart):
        spin = [0, 0, 0] + list(chart.approach)
    elif isinstance(chart, EulerZXZChart):
        spin = [0, 0, 0, 0, 0, 1]
    else:
        instance(chart, "chart", "view_projection", (PoseChart, EulerZXZChart), error=PathError)
    check_view(view, "view_projection")
    u, v = (list(sympy.nsimplify(c, rational=False) for c in axis) for axis in (view.axis_u, view.axis_v))
    return GivenVelocityProjection(chart, [spin, u + [0, 0, 0], v + [0, 0, 0]], name=name)


class Surface(abc.ABC):
    """A workpiece surface (see the module docstring)."""

    name = "surface"

    @abc.abstractmethod
    def default_view(self) -> ViewPlane:
        """The ViewPlane patterns on this surface are drawn in by default. Its origin is where a pattern's
        ``center`` (u, v) = (0, 0) lies: the plane's ``point``, the sphere's and the cylinder's ``center``, a
        height map's frame origin (``X_WM``'s translation)."""

    @abc.abstractmethod
    def implicit(self, p: sympy.Matrix, offset: float) -> sympy.Expr:
        """f_r(p) as a sympy expression of the sympy column ``p``: the signed distance from the surface
        offset by ``offset`` along its outward normal (negative inside), so |grad f_r| = 1 wherever the pad
        can be, on the offset surface and pressed into it: the force row reads the normal force in N."""

    @abc.abstractmethod
    def closest_point(self, p: ArrayLike) -> Tuple[Array, Array]:
        """(q, n): the surface point nearest to ``p`` and the outward unit normal there (floats)."""

    @abc.abstractmethod
    def lift(self, view: ViewPlane, u: float, v: float) -> Tuple[Array, Array]:
        """(q, n): the surface point seen at (u, v) of ``view`` (the line along -w meets it first);
        PathError if it misses the surface."""

    def normal(self, p: ArrayLike) -> Array:
        """The outward unit normal of the offset surface through ``p`` (the same as at its closest point)."""
        return self.closest_point(p)[1]

    def held_normal(self, p: ArrayLike, offset: float) -> Array:
        """The unit direction along which the orientation rows of ``offset_constraint`` hold the approach
        vector (a = -it) at a point ``p`` near the offset surface: grad f_r(p) normalized (here the normal
        of the offset family through p, the same along the normal line)."""
        check_offset(offset, f"{self.name}.held_normal")
        return self.normal(p)

    def offset_constraint(self, chart: Union[PoseChart, EulerZXZChart], offset: float,
                          name: Optional[str] = None) -> ConstraintLike:
        """The constraint on a point held ``offset`` along the outward normal (a ball pad's centre):
        ``surface_constraint`` of f_r, with the orientation rows (a along -grad f_r) as kinematic rows."""
        check_chart(chart, f"{self.name}.offset_constraint")
        offset = check_offset(offset, f"{self.name}.offset_constraint")
        return surface_constraint(chart, lambda p: self.implicit(p, offset), name=name or self.name,
                                  normal_rows=True)

    def signed_distance(self, p: ArrayLike) -> float:
        """Distance of ``p`` from the surface, positive outside."""
        p = check_point(p, f"{self.name}.signed_distance")
        q, n = self.closest_point(p)
        return float((p - q) @ n)


def _largest_root(a, b, c, where):
    """The larger root of a lambda^2 + 2 b lambda + c = 0 (PathError if none is real)."""
    discriminant = b * b - a * c
    if a <= 1e-15 or discriminant < 0:
        raise PathError(f"{where}: the view's line misses the surface")
    return (-b + math.sqrt(discriminant)) / a


class PlaneSurface(Surface):
    """The plane through ``point`` with outward normal ``normal``."""

    def __init__(self, point: ArrayLike, normal: ArrayLike, name: str = "plane") -> None:
        self.name = text(name, "name", "PlaneSurface", error=PathError)
        self.point = _vector(point, f"{name}.point", "PlaneSurface")
        self.unit_normal = _unit(normal, f"{name}.normal", "PlaneSurface")

    def default_view(self) -> ViewPlane:
        """Seen along the normal: origin at ``point``, w = the normal, u = e x n with e the world axis least
        along n (so u is horizontal for a plane that is not)."""
        n = self.unit_normal
        helper = np.eye(3)[int(np.argmin(np.abs(n)))]
        u = np.cross(helper, n)
        return ViewPlane.make(self.point, u, np.cross(n, u))

    def implicit(self, p: sympy.Matrix, offset: float) -> sympy.Expr:
        n, o, offset = self.unit_normal, self.point, check_offset(offset, f"{self.name}.implicit")
        return sum(sympy.Float(n[i]) * (p[i] - sympy.Float(o[i])) for i in range(3)) - sympy.Float(offset)

    def closest_point(self, p: ArrayLike) -> Tuple[Array, Array]:
        p = check_point(p, f"{self.name}.closest_point")
        return p - ((p - self.point) @ self.unit_normal) * self.unit_normal, self.unit_normal.copy()

    def lift(self, view: ViewPlane, u: float, v: float) -> Tuple[Array, Array]:
        start, w = check_view(view, f"{self.name}.lift").point(u, v), view.normal
        facing = float(self.unit_normal @ w)
        if abs(facing) < 1e-12:
            raise PathError(f"{self.name}: the view's normal lies in the plane; the view sees it edge-on")
        lam = -float((start - self.point) @ self.unit_normal) / facing
        return start + lam * w, self.unit_normal.copy()


class SphereSurface(Surface):
    """The sphere of ``radius`` about ``center``."""

    def __init__(self, center: ArrayLike, radius: float, name: str = "sphere") -> None:
        self.name = text(name, "name", "SphereSurface", error=PathError)
        self.center = _vector(center, f"{name}.center", "SphereSurface")
        self.radius = positive(radius, f"{name}.radius", "SphereSurface", unit="m", error=PathError)

    def default_view(self) -> ViewPlane:
        """Seen from above (+z): origin at the centre, u = x, v = y."""
        return ViewPlane.make(self.center)

    def implicit(self, p: sympy.Matrix, offset: float) -> sympy.Expr:
        rho = sympy.Float(self.radius + check_offset(offset, f"{self.name}.implicit"))
        P = [p[i] - sympy.Float(self.center[i]) for i in range(3)]
        return sympy.sqrt(sum(c * c for c in P)) - rho          # the signed distance: |grad f_r| = 1

    def closest_point(self, p: ArrayLike) -> Tuple[Array, Array]:
        d = check_point(p, f"{self.name}.closest_point") - self.center
        norm = float(np.linalg.norm(d))
        if norm < 1e-12:
            raise PathError(f"{self.name}: the centre has no closest surface point")
        n = d / norm
        return self.center + self.radius * n, n

    def lift(self, view: ViewPlane, u: float, v: float) -> Tuple[Array, Array]:
        start, w = check_view(view, f"{self.name}.lift").point(u, v), view.normal
        d = start - self.center
        lam = _largest_root(1.0, float(d @ w), float(d @ d) - self.radius ** 2, f"{self.name} at (u, v) = ({u:.4g}, "
                                                                                  f"{v:.4g}) m")
        return self.closest_point(start + lam * w)


class CylinderSurface(Surface):
    """The cylinder of ``radius`` about the axis through ``center`` along ``axis``; ``length`` (m, default
    unbounded) limits it to |(p - center) . axis| <= length / 2."""

    def __init__(self, center: ArrayLike, axis: ArrayLike, radius: float, length: float = math.inf,
                 name: str = "cylinder") -> None:
        self.name = text(name, "name", "CylinderSurface", error=PathError)
        self.center = _vector(center, f"{name}.center", "CylinderSurface")
        self.axis = _unit(axis, f"{name}.axis", "CylinderSurface")
        self.radius = positive(radius, f"{name}.radius", "CylinderSurface", unit="m", error=PathError)
        self.length = positive(length, f"{name}.length", "CylinderSurface", unit="m", allow_infinite=True,
                               error=PathError)

    def default_view(self) -> ViewPlane:
        """Seen from the world +z (or +x for a vertical axis): origin at ``center``, u along the axis."""
        up = np.array([0.0, 0.0, 1.0]) if abs(self.axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        w = up - (up @ self.axis) * self.axis
        w /= np.linalg.norm(w)
        return ViewPlane.make(self.center, self.axis, np.cross(w, self.axis))

    def _radial(self, d):
        return d - (d @ self.axis) * self.axis

    def implicit(self, p: sympy.Matrix, offset: float) -> sympy.Expr:
        rho = sympy.Float(self.radius + check_offset(offset, f"{self.name}.implicit"))
        k = [sympy.Float(c) for c in self.axis]
        d = [p[i] - sympy.Float(self.center[i]) for i in range(3)]
        along = sum(k[i] * d[i] for i in range(3))
        radial = [d[i] - along * k[i] for i in range(3)]
        return sympy.sqrt(sum(c * c for c in radial)) - rho     # the signed distance: |grad f_r| = 1

    def closest_point(self, p: ArrayLike) -> Tuple[Array, Array]:
        p = check_point(p, f"{self.name}.closest_point")
        d = p - self.center
        radial = self._radial(d)
        norm = float(np.linalg.norm(radial))
        if norm < 1e-12:
            raise PathError(f"{self.name}: a point on the axis has no closest surface point")
        n = radial / norm
        return p - radial + self.radius * n, n

    def lift(self, view: ViewPlane, u: float, v: float) -> Tuple[Array, Array]:
        start, w = check_view(view, f"{self.name}.lift").point(u, v), view.normal
        d, w_radial = self._radial(start - self.center), self._radial(w)
        where = f"{self.name} at (u, v) = ({u:.4g}, {v:.4g}) m"
        lam = _largest_root(float(w_radial @ w_radial), float(d @ w_radial), float(d @ d) - self.radius ** 2, where)
        point = start + lam * w
        if abs(float((point - self.center) @ self.axis)) > self.length / 2:
            raise PathError(f"{where}: beyond the cylinder's length ({self.length:g} m)")
        return self.closest_point(point)
