"""A workpiece given as data: a height map z = h(x, y) on a grid (a scanned part).

``HeightMap`` holds the samples (``HeightMap.from_file``: CSV or NumPy; checked: finite, at least
``MIN_SAMPLES`` per axis, increasing coordinates). ``HeightMapSurface`` makes it a ``core.surfaces``
surface, so paths and patterns work on it as on the analytic ones:

* the surface: an interpolating quintic spline h (its derivatives up to the fourth are
  continuous: the constraint's curvature terms use the third, their AutoDiffXd gradients the
  fourth);
* the pad centre's surface: a ball of radius r rolling on the part keeps its centre on the offset
  surface z = H_r(x, y) (``offset_field``): for each grid node the contact point q with
  q_xy + r n_xy(q) = (x, y) is found by Newton's method, H_r = h(q) + r n_z(q), and H_r is
  splined like h. A ball that would touch the part twice (a concave radius below r, a valley
  narrower than the pad) is refused (PathError naming where);
* the constraint: ``core.height_field.HeightFieldConstraint`` of H_r (the distance to the offset
  surface to second order, its force the normal force in N where the pad is pressed in too, and two
  kinematic rows holding the approach vector along the normal), exact to the second derivative in float
  and AutoDiffXd;
* the workpiece's geometry: ``mesh`` gives a closed triangle mesh of the part (the surface sampled
  from the same spline, sides and a bottom), for a rigid hydroelastic Mesh.

Coordinates: the grid is given in the map's frame M (x right, y up the rows, z the height);
``X_WM`` places it in the world. File layout: a matrix of heights, one row per y and one column
per x (an image's layout), with ``spacing`` (dx, dy) and ``origin`` (x, y of the first sample);
a ``.npz`` may instead hold arrays ``x``, ``y`` and ``heights``.
"""

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Iterable, Optional, Tuple, Union

import numpy as np
import sympy
from numpy.typing import ArrayLike

from pydrake.math import RigidTransform

from drake_hybrid.core.arguments import instance
from drake_hybrid.core.charts import EulerZXZChart, PoseChart
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.height_field import DEGREE, HeightField, HeightFieldConstraint
from drake_hybrid.core.hints import Array, VectorLike
from drake_hybrid.core.surfaces import Surface, ViewPlane, check_chart

MIN_SAMPLES = DEGREE + 1          # per axis: a quintic spline needs six samples


@dataclass
class HeightMap:
    """Heights ``heights[j, i]`` = h(x[i], y[j]) on a grid (m)."""

    x: Array
    y: Array
    heights: Array
    name: str = "height map"

    def __post_init__(self):
        self.x = np.asarray(self.x, dtype=float).reshape(-1)
        self.y = np.asarray(self.y, dtype=float).reshape(-1)
        self.heights = np.asarray(self.heights, dtype=float)
        self.validate()

    def validate(self) -> None:
        """PathError (one line, naming the map) for a grid the surface cannot be made from."""
        heights, where = self.heights, self.name
        if heights.ndim != 2:
            raise PathError(f"{where}: heights must be a 2-D grid (one row per y, one column per x), got "
                            f"{heights.ndim} dimension(s)")
        rows, columns = heights.shape
        if rows < MIN_SAMPLES or columns < MIN_SAMPLES:
            raise PathError(f"{where}: {columns} x {rows} samples (x by y) are too few; at least {MIN_SAMPLES} per "
                            "axis are needed for a smooth surface with continuous curvature")
        bad = np.argwhere(~np.isfinite(heights))
        if bad.size:
            j, i = bad[0]
            raise PathError(f"{where}: {len(bad)} height(s) missing or not finite, the first at row {j}, column {i} "
                            f"(value {heights[j, i]}); fill the holes of the scan before using it")
        for name, axis, count in (("x", self.x, columns), ("y", self.y, rows)):
            if axis.shape != (count,):
                raise PathError(f"{where}: {name} must have {count} coordinates (one per grid "
                                f"{'column' if name == 'x' else 'row'}), got {axis.size}")
            if not np.all(np.isfinite(axis)) or not np.all(np.diff(axis) > 0):
                raise PathError(f"{where}: the {name} coordinates must be finite and strictly increasing")

    @staticmethod
    def from_file(path: Union[str, Path], spacing: Optional[ArrayLike] = None,
                  origin: VectorLike = (0.0, 0.0)) -> "HeightMap":
        """A HeightMap from ``path``: .csv or .npy (a matrix of heights; ``spacing`` (dx, dy) in m and
        ``origin`` (x, y) of the first sample required) or .npz (``heights``, and ``x``, ``y`` or a spacing)."""
        path = Path(path)
        if not path.is_file():
            raise PathError(f"height map file '{path}' does not exist")
        suffix = path.suffix.lower()
        x = y = None
        try:
            if suffix == ".csv":
                heights = np.loadtxt(path, delimiter=",", ndmin=2)
            elif suffix == ".npy":
                heights = np.load(path, allow_pickle=False)
            elif suffix == ".npz":
                with np.load(path, allow_pickle=False) as data:
                    if "heights" not in data:
                        raise PathError(f"{path}: a .npz height map needs an array 'heights' (and 'x', 'y' or a "
                                        f"spacing), got {sorted(data.files)}")
                    heights = data["heights"]
                    x, y = (data[k] if k in data else None for k in ("x", "y"))
            else:
                raise PathError(f"height map file '{path}': the format must be .csv, .npy or .npz")
        except ValueError as error:
            raise PathError(f"{path}: not a grid of numbers ({str(error).splitlines()[0]})") from None
        heights = np.asarray(heights, dtype=float)
        if x is None or y is None:
            if spacing is None:
                raise PathError(f"{path}: give the grid's spacing (dx, dy) in m")
            dx, dy = (float(s) for s in np.broadcast_to(np.asarray(spacing, dtype=float), (2,)))
            if not (0 < dx < math.inf and 0 < dy < math.inf):
                raise PathError(f"{path}: the spacing must be positive (m), got {list(np.atleast_1d(spacing))}")
            x0, y0 = (float(o) for o in origin)
            rows, columns = heights.shape if heights.ndim == 2 else (0, 0)
            x, y = x0 + dx * np.arange(columns), y0 + dy * np.arange(rows)
        return HeightMap(x, y, heights, name=f"height map '{path.name}'")

    def digest(self) -> str:
        """A short hash of the samples (names cached meshes and offsets)."""
        return hashlib.sha256(b"".join(a.tobytes() for a in (self.x, self.y, self.heights))).hexdigest()[:16]


class HeightMapSurface(Surface):
    """A ``core.surfaces.Surface`` from a ``HeightMap`` placed at ``X_WM`` (see the module docstring)."""

    def __init__(self, height_map: HeightMap, X_WM: Optional[RigidTransform] = None,
                 name: Optional[str] = None) -> None:
        self.height_map = instance(height_map, "height_map", "HeightMapSurface", HeightMap,
                                   what="a HeightMap (HeightMap.from_file)", error=PathError)
        self.name = name or height_map.name
        X_WM = instance(X_WM, "X_WM", "HeightMapSurface", RigidTransform, allow_none=True, error=PathError)
        if X_WM is not None and not np.all(np.isfinite(X_WM.GetAsMatrix4())):
            raise PathError(f"HeightMapSurface: X_WM must be a RigidTransform of finite numbers, got translation "
                            f"{X_WM.translation().tolist()}")
        self.X_WM = X_WM if X_WM is not None else RigidTransform()
        self.field = HeightField(height_map.x, height_map.y, height_map.heights, self.X_WM, self.name)
        self._offsets: Dict[float, HeightField] = {}

    # -- Surface ---------------------------------------------------------------------------------
    def default_view(self) -> ViewPlane:
        """The map's own xy plane, seen from above (+Z)."""
        R = self.X_WM.rotation().matrix()
        return ViewPlane.make(self.X_WM.translation(), R[:, 0], R[:, 1])

    def implicit(self, p: sympy.Matrix, offset: float) -> sympy.Expr:
        raise TypeError(f"{self.name}: a height map has no closed-form f(p); use offset_constraint")

    def offset_constraint(self, chart: Union[PoseChart, EulerZXZChart], offset: float,
                          name: Optional[str] = None) -> HeightFieldConstraint:
        check_chart(chart, f"{self.name}.offset_constraint")
        return HeightFieldConstraint(chart, self.offset_field(offset), name=name or self.name)

    def held_normal(self, p: ArrayLike, offset: float) -> Array:
        """grad (Z - H_r(X, Y)) at p's (X, Y), normalized: what the constraint's orientation rows hold a
        against. Not constant along the normal line: 1 mm inside the offset surface (a pressed pad) it
        turns by about 1 mm x |H_r''| (0.3 deg on the bump's flank), so a start pressed along the
        normal must take its orientation from here, not from the surface point's normal."""
        field = self.offset_field(offset)
        X, Y = field.map_point(p)[:2]
        return field.normal(X, Y)

    def closest_point(self, p: ArrayLike) -> Tuple[Array, Array]:
        """Newton's method on |p - (X, Y, h(X, Y))|^2 in the map's frame, from p's own (X, Y)."""
        field = self.field
        target = field.map_point(p)
        X, Y = target[0], target[1]
        for _ in range(30):
            h = field.derivatives(X, Y, 2)
            residual = np.array([X, Y, h[(0, 0)]]) - target
            J = np.array([[1.0, 0.0], [0.0, 1.0], [h[(1, 0)], h[(0, 1)]]])
            gradient = J.T @ residual
            hessian = J.T @ J + residual[2] * np.array([[h[(2, 0)], h[(1, 1)]], [h[(1, 1)], h[(0, 2)]]])
            step = np.linalg.solve(hessian, gradient) if np.linalg.det(hessian) > 1e-12 else gradient
            X, Y = X - step[0], Y - step[1]
            if np.max(np.abs(step)) < 1e-13:
                break
        q = field.world_point([X, Y, float(field(X, Y))])
        return q, field.normal(X, Y)

    def lift(self, view: ViewPlane, u: float, v: float) -> Tuple[Array, Array]:
        """The map point below (u, v) of a view in the map's xy plane."""
        if abs(float(view.normal @ self.X_WM.rotation().matrix()[:, 2])) < 1 - 1e-9:
            raise PathError(f"{self.name}: patterns on a height map are drawn in the map's own xy plane; the "
                            f"view's normal {np.round(view.normal, 3).tolist()} is not the map's z")
        X, Y = self.field.map_point(view.point(u, v))[:2]
        self.check_inside([(X, Y)], 0.0, f"the point (u, v) = ({u:.4g}, {v:.4g}) m")
        return self.field.world_point([X, Y, float(self.field(X, Y))]), self.field.normal(X, Y)

    def check_inside(self, map_points: Iterable[Tuple[float, float]], margin: float, what: str) -> None:
        """PathError if a map-frame point (X, Y) is not ``margin`` inside the map's grid."""
        x0, x1, y0, y1 = self.field.bounds
        for X, Y in map_points:
            if not (x0 + margin <= X <= x1 - margin and y0 + margin <= Y <= y1 - margin):
                raise PathError(f"{self.name}: {what} is at map (x, y) = ({X:.4g}, {Y:.4g}) m, outside the grid's "
                                f"[{x0 + margin:.4g}, {x1 - margin:.4g}] x [{y0 + margin:.4g}, {y1 - margin:.4g}] m "
                                f"(the grid less {margin * 1000:.3g} mm)")

    # -- the pad centre's surface ------------------------------------------------------------------
    def offset_field(self, offset: float) -> HeightField:
        """The HeightField H_r of the ball's centre (radius ``offset``) rolling on the part."""
        offset = float(offset)
        if offset not in self._offsets:
            self._offsets[offset] = self.field if offset == 0 else self._dilate(offset)
        return self._offsets[offset]

    def _contact(self, X, Y, r):
        """(contact X, Y, det of the map from contact to centre) with q_xy + r n_xy(q) = (X, Y)."""
        field = self.field

        def centre(a, b):
            h = field.derivatives(a, b, 2)
            s = math.sqrt(1.0 + h[(1, 0)] ** 2 + h[(0, 1)] ** 2)
            n = np.array([-h[(1, 0)], -h[(0, 1)]]) / s
            # d n_xy / d(a, b) = -(I - n n^T restricted) H2 / s  (the xy block of the unit normal's derivative)
            H2 = np.array([[h[(2, 0)], h[(1, 1)]], [h[(1, 1)], h[(0, 2)]]])
            g = np.array([h[(1, 0)], h[(0, 1)]])
            dn = -(H2 / s) + np.outer(g, g @ H2) / s ** 3
            return np.array([a, b]) + r * n, np.eye(2) + r * dn

        a, b = X, Y
        for _ in range(50):
            point, jacobian = centre(a, b)
            step = np.linalg.solve(jacobian, point - np.array([X, Y]))
            a, b = a - step[0], b - step[1]
            if np.max(np.abs(step)) < 1e-14:
                break
        return a, b, float(np.linalg.det(centre(a, b)[1]))

    def _dilate(self, r):
        field, hm = self.field, self.height_map
        spacing = 0.5 * min(np.min(np.diff(hm.x)), np.min(np.diff(hm.y)))
        x = np.linspace(hm.x[0], hm.x[-1], min(400, int(math.ceil((hm.x[-1] - hm.x[0]) / spacing)) + 1))
        y = np.linspace(hm.y[0], hm.y[-1], min(400, int(math.ceil((hm.y[-1] - hm.y[0]) / spacing)) + 1))
        heights = np.empty((len(y), len(x)))
        on_map = np.zeros((len(y), len(x)), dtype=bool)        # the node's contact point lies on the grid
        x0, x1, y0, y1 = field.bounds
        for j, Y in enumerate(y):
            for i, X in enumerate(x):
                a, b, det = self._contact(X, Y, r)
                if not det > 0.05:
                    raise PathError(f"{self.name}: a pad of radius {r * 1000:.3g} mm cannot roll over the part near "
                                    f"map (x, y) = ({X:.4g}, {Y:.4g}) m: it curves inward more tightly than the pad "
                                    "(its concave radius is below the pad's); smooth the map or use a smaller pad")
                h = field.derivatives(a, b, 1)
                normal_z = 1.0 / math.sqrt(1.0 + h[(1, 0)] ** 2 + h[(0, 1)] ** 2)
                heights[j, i] = h[(0, 0)] + r * normal_z
                on_map[j, i] = x0 <= a <= x1 and y0 <= b <= y1
        self._check_single_contact(x, y, heights, r, on_map)
        return HeightField(x, y, heights, self.X_WM, f"{self.name} offset by {r * 1000:.3g} mm")

    def _check_single_contact(self, x, y, centres, r, on_map):
        """PathError where the ball at a node's centre would reach below the part elsewhere (two contacts);
        nodes whose contact point lies off the grid (the spline extrapolated there) are not checked: the
        pad's path keeps its contact points on the grid (``check_inside``)."""
        angles = np.linspace(0.0, 2 * math.pi, 24, endpoint=False)
        radii = np.linspace(0.1, 1.0, 8) * r
        dx = np.outer(radii, np.cos(angles)).ravel()
        dy = np.outer(radii, np.sin(angles)).ravel()
        x0, x1, y0, y1 = self.field.bounds
        tolerance = 1e-6 + 1e-3 * r
        for j in range(0, len(y), 2):
            for i in range(0, len(x), 2):
                if not on_map[j, i]:
                    continue
                X, Y = x[i] + dx, y[j] + dy
                inside = (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1)
                ball_bottom = centres[j, i] - np.sqrt(np.maximum(r * r - dx ** 2 - dy ** 2, 0.0))
                reach = self.field(X[inside], Y[inside]) - ball_bottom[inside]
                if reach.size and reach.max() > tolerance:
                    raise PathError(f"{self.name}: a pad of radius {r * 1000:.3g} mm resting near map (x, y) = "
                                    f"({x[i]:.4g}, {y[j]:.4g}) m would touch the part twice (a valley narrower than "
                                    "the pad); smooth the map or use a smaller pad")

    # -- geometry for the plant --------------------------------------------------------------------
    def mesh(self, resolution: float = 0.002, thickness: float = 0.02) -> Tuple[Array, Array]:
        """(vertices (N x 3), triangles (M x 3), 0-based, outward) of the closed part in the map's frame:
        the top sampled from the spline every ``resolution`` m (at most), sides down to ``thickness`` m
        below the lowest sample, and a bottom."""
        hm = self.height_map
        nx = max(2, int(math.ceil((hm.x[-1] - hm.x[0]) / resolution)) + 1)
        ny = max(2, int(math.ceil((hm.y[-1] - hm.y[0]) / resolution)) + 1)
        x, y = np.linspace(hm.x[0], hm.x[-1], nx), np.linspace(hm.y[0], hm.y[-1], ny)
        top = self.field.spline(x, y)                                  # (nx, ny)
        bottom = float(np.min(top)) - float(thickness)
        X, Y = np.meshgrid(x, y, indexing="ij")
        vertices = [np.column_stack([X.ravel(), Y.ravel(), top.ravel()])]
        index = np.arange(nx * ny).reshape(nx, ny)
        a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
        triangles = [np.column_stack([a, b, c]), np.column_stack([a, c, d])]   # counterclockwise seen from +z
        # The boundary loop (counterclockwise from above), then the sides and a fan for the bottom.
        loop = np.concatenate([index[:, 0], index[-1, 1:], index[-2::-1, -1], index[0, -2:0:-1]])
        base = nx * ny
        ring = np.array([vertices[0][k] for k in loop])
        vertices.append(np.column_stack([ring[:, 0], ring[:, 1], np.full(len(loop), bottom)]))
        count = len(loop)
        following = np.roll(np.arange(count), -1)
        triangles.append(np.column_stack([loop, base + np.arange(count), base + following]))
        triangles.append(np.column_stack([loop, base + following, loop[following]]))
        centre = base + count
        vertices.append(np.array([[0.5 * (x[0] + x[-1]), 0.5 * (y[0] + y[-1]), bottom]]))
        triangles.append(np.column_stack([np.full(count, centre), base + following, base + np.arange(count)]))
        return np.vstack(vertices), np.vstack(triangles)
