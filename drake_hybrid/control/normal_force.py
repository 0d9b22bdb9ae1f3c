"""Which force the normal row reads: along the model's normal, or along the tool's own axis.

The constraint's force row of the surface (its first force-controlled row, C_1 = the distance to the
model's surface) reads, in E's dual basis, the force along the **model's** normal n. On a surface the
model gets wrong, a flat tool whose orientation rows are force-controlled (zero moment) lies flat on the
**real** surface; its axis a (the end-effector frame's z, the approach vector) is then the real normal, and
the normal force the user commands is the force along a, not along n: with the model 8 deg off, F . n
= 20 N is F . a = 20 / cos 8 deg = 20.2 N.

With ``normal_force_axis="tool"`` the law reads the measured force changed along n only, so that the
normal row reads the force along the tool's axis (a signed towards n)::

    f' = f + ((a_n . f - F_1(f)) / F_1(n)) n        a_n = sign(a . n) a,  n the unit model normal

F_1 the row's reading in E's dual basis (``control.law.measured_forces``; where E_p's rows are orthogonal to
n, F_1(f) = n . f and f' = f + ((a_n - n) . f) n). The normal row then holds a_n . f. The other rows' readings
do not change: their dual vectors are orthogonal to the normal row's direction n (E E^-1 = I, the normal row
a distance, with no moment part). At a tool aligned with a frictionless contact (f along a) a small tilt
changes a_n . f only to second order, so the loop's linearization is the model's. "model" (the default)
reads f as measured.
"""

from typing import Any, Callable, Tuple

import numpy as np

from pydrake.math import sqrt

from drake_hybrid.core.hints import Array

NORMAL_FORCE_AXES = ("model", "tool")


def normal_row(force_size: int, kinematic_rows: Tuple[int, ...]) -> int:
    """The normal row: the constraint's first force-controlled (not kinematic) row."""
    return next(i for i in range(force_size) if i not in kinematic_rows)


def model_normal(chart: Any, force_projection: Array, x: Array, row: int) -> Array:
    """The unit direction in world of the force that row ``row`` of E_f reads at chart configuration ``x``:
    the translational part of the row as a covector on the spatial velocity [w; v]
    (E_f nu = E_f L V, L = ``chart.task_jacobian(x, I)``). ValueError if the row has no translational part."""
    covector = force_projection[row] @ chart.task_jacobian(x, np.eye(6))
    direction = covector[3:]
    length_squared = direction @ direction
    if not length_squared > 1e-24:
        raise ValueError(f"HybridController: normal_force_axis='tool' needs the normal row {row} of E_f to read a "
                         "force (a translational part); at this configuration it reads moments only")
    return direction / sqrt(length_squared)


def force_along_tool_axis(wrench: Array, normal: Array, axis: Array, reading: Callable[[Array], Any]) -> Array:
    """The wrench [n; f] changed along ``normal`` (unit) so that the normal row's ``reading`` of it (a linear
    function of a wrench: the row's dual vector in E's dual basis) is the force along ``axis`` (unit, the tool's,
    signed towards ``normal``): the module docstring's f', W' = W + ((a_n . f - reading(W)) / reading([0; n]))
    [0; n]. Float or AutoDiffXd."""
    signed = axis if axis @ normal >= 0 else -axis
    along_normal = np.concatenate([np.zeros(3), normal])
    unit_reading = reading(along_normal)
    if not abs(unit_reading) > 1e-9:
        raise ValueError("HybridController: normal_force_axis='tool': the normal row does not read the force "
                         "along the model's normal at this configuration")
    return wrench + ((signed @ wrench[3:] - reading(wrench)) / unit_reading) * along_normal


def tool_axis_wrench(space: Any, configuration: Array, rotation: Array, wrench: Array, values: Any = None) -> Array:
    """The measured spatial ``wrench`` as the normal row reads it with ``normal_force_axis="tool"``: changed along
    the model's normal so that the row's reading in E's dual basis (``space.split_wrench``) is the force along the
    tool's axis (``rotation``'s z, R_WE of the end-effector frame), at chart ``configuration`` x. ``values``:
    ``space.evaluate`` at x, if already computed. Float or AutoDiffXd."""
    chart = space.chart
    if values is None:
        values = space.evaluate(configuration, np.zeros(chart.velocity_size), check=False)
    row = normal_row(space.force_size, tuple(space.constraint.kinematic_rows))
    normal = model_normal(chart, values.force_projection, configuration, row)

    def reading(spatial_wrench: Array) -> Any:
        return space.split_wrench(values, chart.generalized_force(configuration, spatial_wrench))[1][row]

    return force_along_tool_axis(np.asarray(wrench), normal, rotation[:, 2], reading)
