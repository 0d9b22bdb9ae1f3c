"""Coverage patterns drawn in a view plane: raster (boustrophedon) and spiral.

A pattern is a list of strokes, each a polyline of (u, v) points (m) in a ``core.surfaces.ViewPlane``;
``core.paths.surface_path`` lifts them onto the surface. A raster's strokes are its lines and the
short steps between them (the pad stops at each corner: every stroke is a segment from rest to
rest); a spiral is one smooth stroke.

``raster(center, size, spacing, direction)``
    lines parallel to u (``direction`` "u") or v, ``spacing`` apart, covering the rectangle of
    ``size`` (width along u, height along v) about ``center``; the first line at one edge, the last
    at the other (the spacing is shrunk evenly so the lines end on the edges).
``spiral(center, radius, spacing)``
    an Archimedean spiral r = spacing theta / (2 pi) from the centre out to ``radius``, sampled
    every ``step`` m of its length (it starts half a turn out, where its curvature is finite).

Bad input (a spacing or a size that is not positive, a spacing larger than the region, a string or
a bool where a number goes) is a ``PathError`` naming the field. So is a pattern of more than
``MAX_PATH_POINTS`` samples (a spacing too fine for its region), refused before it is drawn.
"""

import math

import numpy as np

from drake_hybrid.core.arguments import describe, numeric_array, positive, text, vector
from drake_hybrid.core.errors import PathError

STEP = 0.001        # m between the samples of a stroke
# The most samples a path (a pattern, or the strokes between waypoints) may have: 100 m of path at STEP,
# e.g. a 0.7 m x 0.7 m panel rastered at 5 mm. Building a path takes about 0.4 ms a sample (Toppra and
# the splines; measured on this project's machine: 40 s for the bound) and a job runs it at the path's
# speed (2000 s simulated at 0.05 m/s), so a larger pattern is a spacing mistaken by orders of magnitude
# (1e-5 m asks for a million samples on a 0.1 m square): refused before its points are made.
MAX_PATH_POINTS = 100_000


def check_point_count(count, where, advice):
    """PathError if a path of ``count`` samples exceeds MAX_PATH_POINTS (``where``: what asked for them;
    ``advice``: what to change)."""
    if count > MAX_PATH_POINTS:
        raise PathError(f"{where} would take {count:.3g} samples, more than {MAX_PATH_POINTS} (100 m of path at "
                        f"{STEP * 1000:g} mm): {advice}")


def check_strokes(strokes, what, owner):
    """The strokes as arrays of (u, v) points (at least one stroke of at least two finite points each, at most
    MAX_PATH_POINTS in all), else a PathError naming ``what``'s strokes and ``owner``."""
    if isinstance(strokes, (str, bytes, dict)) or not hasattr(strokes, "__iter__"):
        raise PathError(f"{owner}: {what} strokes must be a list of (u, v) polylines, got {describe(strokes)}")
    arrays = []
    for index, stroke in enumerate(strokes):
        name = f"{what} strokes[{index}]"
        array = numeric_array(stroke, name, owner, what="a polyline of (u, v) points (m)", error=PathError)
        if array.ndim != 2 or array.shape[1] != 2 or len(array) < 2:
            raise PathError(f"{owner}: {name} must be a polyline of at least two finite (u, v) points (m), got "
                            f"{describe(stroke)}")
        arrays.append(array)
    if not arrays:
        raise PathError(f"{owner}: {what} strokes must hold at least one stroke (a polyline of (u, v) points), got none")
    check_point_count(sum(len(array) for array in arrays), f"{owner}: {what}'s strokes",
                      "draw the pattern with a coarser spacing or over a smaller region")
    return arrays


def _segment(start, end, step=STEP):
    """Points from ``start`` to ``end`` (both included), at most ``step`` apart."""
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    count = max(2, int(math.ceil(np.linalg.norm(end - start) / step)) + 1)
    return start + np.linspace(0.0, 1.0, count)[:, None] * (end - start)


def raster(center, size, spacing, direction="u", what="pattern"):
    """The strokes of a boustrophedon raster (module docstring)."""
    center = vector(center, f"{what}.center", "raster", 2, unit="u, v in m", error=PathError)
    size = vector(size, f"{what}.size", "raster", 2, unit="width, height in m", error=PathError)
    width, height = (positive(s, f"{what}.size", "raster", unit="m", error=PathError) for s in size)
    spacing = positive(spacing, f"{what}.spacing", "raster", unit="m", error=PathError)
    direction = text(direction, f"{what}.direction", "raster", allowed=("u", "v"), error=PathError)
    along, across = (width, height) if direction == "u" else (height, width)
    if spacing > across:
        raise PathError(f"{what}.spacing ({spacing:g} m) is larger than the region across the lines ({across:g} m)")
    lines = across / spacing + 1
    check_point_count(lines * (along + spacing) / STEP, f"raster: {what}.spacing {spacing:g} m over {along:g} m x "
                      f"{across:g} m", "the spacing is too fine for the region (or the region too large)")
    lines = int(math.ceil(across / spacing - 1e-9)) + 1
    offsets = np.linspace(-across / 2, across / 2, lines)
    strokes = []
    for index, offset in enumerate(offsets):
        ends = [-along / 2, along / 2] if index % 2 == 0 else [along / 2, -along / 2]
        line = [(ends[0], offset), (ends[1], offset)]
        if index > 0:
            strokes.append(_segment(strokes[-1][-1], _oriented(line[0], direction, center)))
        strokes.append(_segment(_oriented(line[0], direction, center), _oriented(line[1], direction, center)))
    return strokes


def _oriented(point, direction, center):
    """(along, across) -> (u, v) about ``center``."""
    along, across = point
    return center + (np.array([along, across]) if direction == "u" else np.array([across, along]))


def spiral(center, radius, spacing, what="pattern", step=STEP):
    """The stroke of an Archimedean spiral (module docstring)."""
    center = vector(center, f"{what}.center", "spiral", 2, unit="u, v in m", error=PathError)
    radius = positive(radius, f"{what}.radius", "spiral", unit="m", error=PathError)
    spacing = positive(spacing, f"{what}.spacing", "spiral", unit="m", error=PathError)
    step = positive(step, "step", "spiral", unit="m", error=PathError)
    if spacing > radius:
        raise PathError(f"{what}.spacing ({spacing:g} m) is larger than the radius ({radius:g} m)")
    b = spacing / (2 * math.pi)
    start, end = math.pi, radius / b
    # Arc length of r = b theta: (b / 2) (theta sqrt(1 + theta^2) + asinh(theta)); sample it evenly.
    length = lambda theta: 0.5 * b * (theta * np.sqrt(1 + theta * theta) + np.arcsinh(theta))
    check_point_count((length(end) - length(start)) / step, f"spiral: {what}.spacing {spacing:g} m out to "
                      f"{radius:g} m", "the spacing (or the step) is too fine for the radius")
    count = max(3, int(math.ceil((length(end) - length(start)) / step)) + 1)
    fine = np.linspace(start, end, 20 * count)
    thetas = np.interp(np.linspace(length(start), length(end), count), length(fine), fine)
    return [center + np.column_stack([b * thetas * np.cos(thetas), b * thetas * np.sin(thetas)])]
