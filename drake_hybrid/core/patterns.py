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

Bad input (a spacing or a size that is not positive, a spacing larger than the region) is a
``PathError`` naming the field.
"""

import math

import numpy as np

from drake_hybrid.core.errors import PathError

STEP = 0.001        # m between the samples of a stroke


def _positive(number, what):
    number = float(number)
    if not 0 < number < math.inf:
        raise PathError(f"{what} must be positive and finite (m), got {number}")
    return number


def _segment(start, end, step=STEP):
    """Points from ``start`` to ``end`` (both included), at most ``step`` apart."""
    start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
    count = max(2, int(math.ceil(np.linalg.norm(end - start) / step)) + 1)
    return start + np.linspace(0.0, 1.0, count)[:, None] * (end - start)


def raster(center, size, spacing, direction="u", what="pattern"):
    """The strokes of a boustrophedon raster (module docstring)."""
    center = np.asarray(center, dtype=float).reshape(-1)
    size = np.asarray(size, dtype=float).reshape(-1)
    if center.shape != (2,) or size.shape != (2,) or not np.all(np.isfinite(center)):
        raise PathError(f"{what}: center and size must be 2 finite numbers each (u, v), got {center.tolist()} and "
                        f"{size.tolist()}")
    width, height = (_positive(s, f"{what}.size") for s in size)
    spacing = _positive(spacing, f"{what}.spacing")
    if direction not in ("u", "v"):
        raise PathError(f"{what}.direction must be 'u' or 'v' (the axis the lines run along), got '{direction}'")
    along, across = (width, height) if direction == "u" else (height, width)
    if spacing > across:
        raise PathError(f"{what}.spacing ({spacing:g} m) is larger than the region across the lines ({across:g} m)")
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
    center = np.asarray(center, dtype=float).reshape(-1)
    if center.shape != (2,) or not np.all(np.isfinite(center)):
        raise PathError(f"{what}.center must be 2 finite numbers (u, v), got {center.tolist()}")
    radius = _positive(radius, f"{what}.radius")
    spacing = _positive(spacing, f"{what}.spacing")
    if spacing > radius:
        raise PathError(f"{what}.spacing ({spacing:g} m) is larger than the radius ({radius:g} m)")
    b = spacing / (2 * math.pi)
    start, end = math.pi, radius / b
    # Arc length of r = b theta: (b / 2) (theta sqrt(1 + theta^2) + asinh(theta)); sample it evenly.
    length = lambda theta: 0.5 * b * (theta * np.sqrt(1 + theta * theta) + np.arcsinh(theta))
    count = max(3, int(math.ceil((length(end) - length(start)) / step)) + 1)
    fine = np.linspace(start, end, 20 * count)
    thetas = np.interp(np.linspace(length(start), length(end), count), length(fine), fine)
    return [center + np.column_stack([b * thetas * np.cos(thetas), b * thetas * np.sin(thetas)])]
