"""The hybrid law's preconditions, checked before the first step in any diagram.

The law needs a constraint whose rows are independent (E_f of full rank m, and E = [E_p; E_f]
invertible) and a desired force that a contact can exert: F_d is the force ON the robot in E_f's
coordinates (docs/theory.md §0), and a contact only pushes, so the pad must be pushed out of the
workpiece, along -F_d in C's coordinates. A violation left to the run ends late and misleading (a
``ConstraintRankError`` deep in ``Simulator.Initialize``, or a pad that pulls away and ends far
off the surface); these checks say it first, in one line:

``check_generic_rank(space)``
    a constraint (or a constraint space) whose rows are dependent everywhere: E_f (or E) rank
    deficient at every one of a fixed set of sampled configurations, e.g. two identical rows.
    ``ConstraintSpace`` and ``HybridController`` call it when they are built.
``check_pushing_force(desired_force, ...)``
    a desired force that pulls: at a start in contact, the measured force pushes against F_d; at
    a start off the surface (the guarded move's approach), the pressing direction n_C = -F_d / |F_d|
    leads away from C = 0, or the surface is farther than the guarded move's reach.
    ``HybridController.check_start`` calls it when the controller first ticks.
"""

import numpy as np

from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.core.errors import ConstraintRankError, DrakeHybridError, ForceSignError, OffConstraintError
from drake_hybrid.core.linalg import rank_margin, value

RANK_SAMPLES = 32            # configurations sampled by check_generic_rank (fixed: the same ones every time)
SAMPLE_BOX = 2.0             # m, positions drawn in [-SAMPLE_BOX, SAMPLE_BOX]^3
PULL_FRACTION = 0.1          # a measured force against F_d beyond this fraction of |F_d| is a pull
SURFACE_TOLERANCE = 1e-4     # units of C: a start off the surface farther than this on the far side


def sample_configurations(chart, count=RANK_SAMPLES, seed=1987):
    """``count`` chart configurations of random poses (uniform rotations, positions in the box),
    the same every call."""
    rng = np.random.default_rng(seed)
    configurations = []
    for _ in range(count):
        quaternion = rng.normal(size=4)
        rotation = RotationMatrix(Quaternion(quaternion / np.linalg.norm(quaternion)))
        position = rng.uniform(-SAMPLE_BOX, SAMPLE_BOX, size=3)
        configurations.append(np.asarray(chart.configuration_of_pose(RigidTransform(rotation, position)),
                                         dtype=float))
    return configurations


def _margins(matrix_at, configurations):
    """rank_margin of ``matrix_at(x)`` at each configuration where it evaluates to finite numbers."""
    margins = []
    for x in configurations:
        try:
            matrix = np.asarray(value(matrix_at(x)), dtype=float)
        except (DrakeHybridError, ArithmeticError, ValueError, np.linalg.LinAlgError):
            continue
        if np.all(np.isfinite(matrix)):
            margins.append((x, matrix, rank_margin(matrix)))
    return margins


def _dependent_rows(samples, tolerance):
    """A pair (i, j) of rows that is dependent at every sample, or None."""
    rows = samples[0][1].shape[0]
    for i in range(rows):
        for j in range(i + 1, rows):
            if all(rank_margin(matrix[[i, j]]) < tolerance for _, matrix, _ in samples):
                return i, j
    return None


def check_generic_rank(space_or_constraint):
    """ConstraintRankError if the constraint's E_f (and, for a ConstraintSpace, E = [E_p; E_f]) has
    lost rank at every sampled configuration where it is finite: its rows are dependent everywhere
    (two identical or proportional rows, a row that is a combination of others), so the law cannot
    run anywhere. A constraint that is finite nowhere on the samples is left to the start's checks."""
    constraint = getattr(space_or_constraint, "constraint", space_or_constraint)
    chart = constraint.chart
    configurations = sample_configurations(chart)
    tolerance = float(getattr(constraint, "rank_tolerance", 1e-3))
    samples = _margins(constraint.force_projection, configurations)
    name = getattr(constraint, "name", "constraint")
    if samples and max(margin for _, _, margin in samples) < tolerance:
        pair = _dependent_rows(samples, tolerance)
        which = (f"rows {pair[0]} and {pair[1]} are dependent (identical or proportional) everywhere"
                 if pair else "its rows are dependent everywhere")
        raise ConstraintRankError(
            f"constraint '{name}': E_f = dC has rank below m = {samples[0][1].shape[0]} at every one of "
            f"{len(samples)} sampled configurations (rank margin at most {max(m for _, _, m in samples):.3g} < "
            f"{tolerance:g}): {which}; give C independent rows (docs/theory.md §2)")
    projection = getattr(space_or_constraint, "velocity_projection", None)
    if projection is None or not samples or not hasattr(projection, "symbolic_terms"):
        return                            # a kernel projection is independent of E_f by construction
    full_rank = [x for x, _, margin in samples if margin >= tolerance]
    stacked = _margins(lambda x: np.vstack([value(projection.matrix(x)), value(constraint.force_projection(x))]),
                       full_rank)
    invertibility = float(getattr(space_or_constraint, "invertibility_tolerance", 1e-3))
    if stacked and max(margin for _, _, margin in stacked) < invertibility:
        raise ConstraintRankError(
            f"E = [E_p; E_f] of constraint '{name}' and velocity projection '{projection.name}' is singular at "
            f"every one of {len(stacked)} sampled configurations where E_f has full rank: E_p's rows are not "
            "one-to-one on ker E_f anywhere (a row of E_p depends on the others or on E_f's; docs/theory.md §3)")


def check_pushing_force(desired_force, force=None, constraint_value=None, force_controlled=None, off_surface=False,
                        max_travel=None, where="the start"):
    """ForceSignError if the desired force F_d (m, the force ON the robot in E_f's coordinates) pulls at
    ``where``; OffConstraintError if the surface is out of the guarded move's reach.

    ``force``: the measured F there (None: no valid measurement). In contact, a measured force
    against F_d (F . F_d / |F_d| < -PULL_FRACTION |F_d|) means the workpiece pushes the pad the other
    way: F_d pulls. ``off_surface``: the start is in free space and the guarded move approaches
    along n_C = -F_d / |F_d| from C = ``constraint_value``: the surface C = 0 must lie ahead,
    -n_C . C >= -SURFACE_TOLERANCE, and within ``max_travel`` (units of C) if given.
    ``force_controlled``: 1 on the rows F_d acts on, 0 on kinematic rows (default: every row).
    Nothing is checked where F_d is zero on every force-controlled row."""
    desired = np.asarray(value(desired_force), dtype=float).reshape(-1)
    mask = np.ones_like(desired) if force_controlled is None else np.asarray(force_controlled, dtype=float)
    commanded = desired * mask
    magnitude = float(np.linalg.norm(commanded))
    if not magnitude > 0:
        return
    convention = ("F_d is the force ON the robot in E_f's coordinates (the rows of dC), and a contact only "
                  "pushes: flip the sign of the desired force")
    if force is not None:
        measured = np.asarray(value(force), dtype=float).reshape(-1)
        pressing = float(measured @ commanded) / magnitude
        if np.isfinite(pressing) and pressing < -PULL_FRACTION * magnitude:
            raise ForceSignError(
                f"the desired force F_d = {np.round(desired, 6).tolist()} pulls at {where}: the workpiece pushes "
                f"the pad with {-pressing:.3g} against it (measured F = {np.round(measured, 6).tolist()}); "
                f"{convention}")
    if off_surface and constraint_value is not None:
        direction = -commanded / magnitude                                    # n_C
        ahead = -float(direction @ np.asarray(value(constraint_value), dtype=float).reshape(-1))
        if ahead < -SURFACE_TOLERANCE:
            raise ForceSignError(
                f"the desired force F_d = {np.round(desired, 6).tolist()} pulls at {where}: off the surface at "
                f"C = {np.round(value(constraint_value), 6).tolist()}, the pressing direction -F_d leads away "
                f"from C = 0 (the surface is {-ahead:.3g} behind); {convention}")
        if max_travel is not None and ahead > max_travel:
            raise OffConstraintError(
                f"the surface C = 0 is {ahead:.3g} (units of C) from {where} along the pressing direction, beyond "
                f"the guarded move's max_travel = {max_travel:g}: the approach would stop (HOLD) before it touches; "
                "start closer or raise max_travel")
