"""The state Jacobian of a closed loop, checked: AutoDiffXd against central differences.

``checked_state_jacobian(diagram, context, A_autodiff)`` differentiates the continuous
dynamics x-dot = f(x) (``diagram.EvalTimeDerivatives``) by central differences, all columns
(a closed loop here has a few dozen states: a few dozen evaluations, cheaper than the AutoDiff
``Linearize`` itself), compares them column by column with the AutoDiffXd Jacobian, and picks
the one to trust:

* column error e_j = max_i |A_ad[i, j] - A_cd[i, j]| (absolute) and
  e_j / max(max_i |A_ad[i, j]|, max_i |A_cd[i, j]|, 1e-8 max |A_cd|) (relative to the
  column's scale);
* a column of the AutoDiffXd Jacobian is kept when its relative error is within
  ``JACOBIAN_TOLERANCE`` at the step or, failing that, at a tenth of it (a stiff contact can
  make the coarse step's truncation error large); a column that disagrees at both steps while
  the two steps agree with each other is replaced by central differences, the result says so
  (``JacobianCheck.used``, ``replaced``) and a ``DerivativeMismatchWarning`` names the worst
  column; a column where the two steps do not agree either is kept (``unresolved``).

Why: Drake 1.51's AutoDiffXd derivative of a hydroelastic contact force is wrong in some
geometries (docs/drake_notes.md, "AutoDiffXd derivatives of hydroelastic contact"), and a wrong
A shows as closed-loop modes that do not exist.

The step of column j is ``epsilon * max(1, |x_j|)``, 1e-5 by default. Measured on the window
task (planar 3R arm, ball pad on the pane): the worst relative column error is that of the
wrist angle (it turns the tessellated pad in the contact), 7e-4 at a step of 1e-4
(truncation), 2.3e-5 at 1e-5, 6e-4 at 1e-6, 3e-3 at 1e-7 and 2e-2 at 1e-8 (rounding in the
contact surface's computation); every other column agrees to 1e-7 or better. The
``JACOBIAN_TOLERANCE`` of 1e-3 is 40 times that floor; a real disagreement is of order 1
(docs/drake_notes.md).
"""

import warnings
from dataclasses import dataclass, field

import numpy as np

from drake_hybrid.core.arguments import describe, number, positive, text
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.station.root_context import check_system_context

JACOBIAN_TOLERANCE = 1e-3          # largest relative column error at which AutoDiffXd is trusted
COLUMN_FLOOR = 1e-8                # relative column errors are scaled by at least this times max |A|
JACOBIAN_STEP = 1e-5               # central-difference step, relative to max(1, |x_j|)


class DerivativeMismatchWarning(UserWarning):
    """The AutoDiffXd Jacobian of a closed loop disagrees with central differences beyond the
    tolerance; the linearization uses the central-difference Jacobian instead."""


@dataclass
class JacobianCheck:
    """How well the AutoDiffXd state Jacobian agrees with central differences, and which is used."""

    max_relative_error: float      # max over columns of the relative column error
    max_absolute_error: float      # max over columns of the absolute column error (A's units, e.g. 1/s^2)
    worst_column: int              # state index of the largest relative column error
    worst_state: str               # its name (as the diagram's state vector is laid out)
    tolerance: float
    epsilon: float
    used: str                      # "autodiff", "central differences" or "autodiff with k column(s) from ..."
    evaluations: int               # time-derivative evaluations spent on the check
    replaced: list = field(default_factory=list)     # states whose column came from central differences
    unresolved: list = field(default_factory=list)   # disagreeing columns where the two steps disagree too
    largest_entry: float = float("nan")   # max |A| (central differences): the scale of the absolute figure

    @property
    def agrees(self):
        return self.max_relative_error <= self.tolerance

    def summary(self):
        """One line for reports, in plain words: how closely AutoDiffXd's A agrees with central
        differences (the largest difference in a column relative to that column's size, the figure
        judged against ``tolerance``), the columns replaced, and which A the eigenvalues come from.
        The absolute figures are in ``as_dict``."""
        verdict = "agree" if self.agrees else "DISAGREE"
        replaced = (f"; replaced by central differences: {', '.join(self.replaced)} (Drake's AutoDiffXd derivative "
                    "of hydroelastic contact, docs/drake_notes.md)" if self.replaced else "")
        unresolved = (f"; {len(self.unresolved)} column(s) where the two steps disagree too: AutoDiffXd kept there"
                      if self.unresolved else "")
        used = {"autodiff": "AutoDiffXd's A", "central differences": "the central-difference A"}.get(
            self.used, self.used.replace("autodiff with", "AutoDiffXd's A with"))
        return (f"Jacobian check (AutoDiffXd vs central differences, step {self.epsilon:g}): {verdict}; the columns "
                f"of AutoDiffXd's A differ from central differences by at most {self.max_relative_error:.2g} of the "
                f"column's size (tolerance {self.tolerance:g}; largest in column {self.worst_state}){replaced}"
                f"{unresolved}; eigenvalues from {used}")

    def as_dict(self):
        return {"max_relative_error": self.max_relative_error, "max_absolute_error": self.max_absolute_error,
                "largest_entry": self.largest_entry, "worst_column": self.worst_column, "worst_state": self.worst_state, "tolerance": self.tolerance,
                "epsilon": self.epsilon, "used": self.used, "agrees": bool(self.agrees),
                "evaluations": self.evaluations, "replaced": self.replaced, "unresolved": self.unresolved}


def central_difference_jacobian(diagram, context, epsilon=JACOBIAN_STEP, columns=None):
    """d(x-dot)/dx of ``diagram``'s continuous state at ``context`` by central differences
    (step ``epsilon * max(1, |x_j|)``), for ``columns`` (default all; the others are left 0);
    ``context`` is left as it was. ArgumentError for a ``context`` that is not ``diagram``'s, an ``epsilon``
    that is not > 0, ``columns`` that are not state indices."""
    owner = "central_difference_jacobian"
    check_system_context(diagram, context, owner)
    epsilon = positive(epsilon, "epsilon", owner, unit="relative step")
    x0 = context.get_continuous_state_vector().CopyToVector()
    if columns is not None:
        if not isinstance(columns, (list, tuple, range, np.ndarray)):
            raise ArgumentError(f"{owner}: columns must be a list of state indices (0 to {x0.size - 1}) or None, "
                                f"got {describe(columns)}")
        columns = [number(j, "columns", owner, low=0, high=x0.size - 1, integer=True) for j in columns]
    work = context.Clone()
    A = np.zeros((x0.size, x0.size))
    for j in (range(x0.size) if columns is None else columns):
        step = epsilon * max(1.0, abs(x0[j]))
        derivatives = []
        for sign in (1.0, -1.0):
            x = x0.copy()
            x[j] += sign * step
            work.SetContinuousState(x)
            derivatives.append(diagram.EvalTimeDerivatives(work).CopyToVector())
        A[:, j] = (derivatives[0] - derivatives[1]) / (2.0 * step)
    return A


def _jacobian(value, name, owner, shape=None):
    """``value`` as a float matrix (of ``shape`` if given; NaN and inf kept: a Jacobian's bad entries are what
    the check finds); ArgumentError naming ``name`` otherwise."""
    try:
        array = None if isinstance(value, (str, bytes)) or value is None else np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is None or array.ndim != 2 or (shape is not None and array.shape != tuple(shape)):
        size = f"a {shape[0]}x{shape[1]} matrix" if shape is not None else "a matrix"
        raise ArgumentError(f"{owner}: {name} must be {size} of numbers, got {describe(value)}")
    return array


def column_errors(A_autodiff, A_differences):
    """(relative, absolute) error of each column of the AutoDiffXd Jacobian against central
    differences. The relative one is scaled by the larger of the two columns' max norms, floored
    at ``COLUMN_FLOOR`` times the largest entry of A: a column that is zero but for rounding (the
    Panda's base joint on a level plane: entries of 1e-9 in a matrix of 1e7) is not compared
    with itself. ArgumentError for two arguments that are not matrices of one shape."""
    A_autodiff = _jacobian(A_autodiff, "A_autodiff", "column_errors")
    A_differences = _jacobian(A_differences, "A_differences", "column_errors", A_autodiff.shape)
    difference = np.max(np.abs(A_autodiff - A_differences), axis=0)
    scale = np.maximum(np.max(np.abs(A_autodiff), axis=0), np.max(np.abs(A_differences), axis=0))
    scale = np.maximum(scale, COLUMN_FLOOR * np.max(np.abs(A_differences), initial=0.0))
    relative = np.divide(difference, scale, out=np.zeros_like(difference), where=scale > 0)
    return relative, difference


def state_names(diagram, context):
    """A name for each continuous state of ``diagram`` ("plant q[2]", "controller x[0]", ...): plant
    positions and velocities by joint, other systems by their name and index."""
    check_system_context(diagram, context, "state_names")
    names = []
    for system in diagram.GetSystems():
        size = system.GetMyContextFromRoot(context).num_continuous_states()
        if size == 0:
            continue
        plant_names = getattr(system, "GetStateNames", None)
        if plant_names is not None and system.get_name() == "plant":
            names.extend(f"plant {name}" for name in plant_names(add_model_instance_prefix=False))
        else:
            names.extend(f"{system.get_name()} x[{i}]" for i in range(size))
    return names


def checked_state_jacobian(diagram, context, A_autodiff, tolerance=JACOBIAN_TOLERANCE, epsilon=JACOBIAN_STEP,
                           what="the closed loop"):
    """The state Jacobian to use for ``diagram`` at ``context``, and the check that chose it.

    Column by column: AutoDiffXd's column is kept when it agrees (relative column error within
    ``tolerance``) with central differences at ``epsilon`` or, for the columns that do not, at
    ``epsilon / 10`` (a step too large for a stiff contact is truncation, not a wrong
    derivative). A column that agrees with neither, while the two steps agree with each other,
    is wrong in AutoDiffXd: the central-difference column (``epsilon / 10``) replaces it, and a
    ``DerivativeMismatchWarning`` (one line: ``what``, the worst column and its errors) says so.
    A column where the two steps disagree with each other as well is left to AutoDiffXd and
    counted as unresolved.

    Returns (A, JacobianCheck). ArgumentError for a ``context`` that is not ``diagram``'s, an ``A_autodiff``
    that is not n x n (n continuous states), a ``tolerance`` or ``epsilon`` that is not > 0 (tolerance inf:
    never replace a column)."""
    owner = "checked_state_jacobian"
    check_system_context(diagram, context, owner)
    size = context.num_continuous_states()
    A_autodiff = _jacobian(A_autodiff, "A_autodiff", owner, (size, size))
    tolerance = positive(tolerance, "tolerance", owner, allow_infinite=True, unit="relative column error")
    epsilon = positive(epsilon, "epsilon", owner, unit="relative step")
    what = text(what, "what", owner)
    A_coarse = central_difference_jacobian(diagram, context, epsilon)
    relative, absolute = column_errors(A_autodiff, A_coarse)
    evaluations = 2 * A_coarse.shape[1]
    doubtful = [int(j) for j in np.flatnonzero(relative > tolerance)]
    replaced, unresolved = [], []
    A = A_autodiff.copy()
    if doubtful:
        A_fine = central_difference_jacobian(diagram, context, epsilon / 10.0, columns=doubtful)
        evaluations += 2 * len(doubtful)
        relative_fine, absolute_fine = column_errors(A_autodiff, A_fine)
        # The two steps against each other, on the same scale as against AutoDiffXd (a column that is
        # about zero in central differences and large in AutoDiffXd is consistent, not noise over noise).
        step_difference = np.max(np.abs(A_coarse - A_fine), axis=0)
        scale = np.maximum.reduce([np.max(np.abs(M), axis=0) for M in (A_autodiff, A_coarse, A_fine)])
        scale = np.maximum(scale, COLUMN_FLOOR * np.max(np.abs(A_coarse), initial=0.0))
        consistency = np.divide(step_difference, scale, out=np.zeros_like(scale), where=scale > 0)
        for j in doubtful:
            if relative_fine[j] <= relative[j]:
                relative[j], absolute[j] = relative_fine[j], absolute_fine[j]
            if relative[j] <= tolerance:
                continue                                   # truncation at the coarse step
            if consistency[j] <= tolerance:
                A[:, j] = A_fine[:, j]
                replaced.append(j)
            else:
                unresolved.append(j)
    worst = int(np.argmax(relative)) if relative.size else 0
    names = state_names(diagram, context)
    name = lambda j: names[j] if j < len(names) else f"x[{j}]"
    used = "autodiff"
    if replaced:
        used = ("central differences" if len(replaced) == A.shape[1]
                else f"autodiff with {len(replaced)} column(s) from central differences")
    check = JacobianCheck(max_relative_error=float(relative.max(initial=0.0)),
                          max_absolute_error=float(absolute.max(initial=0.0)), worst_column=worst,
                          worst_state=name(worst), tolerance=tolerance, epsilon=epsilon, used=used,
                          evaluations=evaluations, replaced=[name(j) for j in replaced],
                          unresolved=[name(j) for j in unresolved],
                          largest_entry=float(np.max(np.abs(A_coarse), initial=0.0)))
    if replaced:
        warnings.warn(DerivativeMismatchWarning(
            f"{what}: the AutoDiffXd state Jacobian disagrees with central differences (column {name(worst)}: "
            f"{check.max_relative_error:.2g} relative, {absolute[worst]:.3g} absolute, tolerance {tolerance:g}; "
            f"steps {epsilon:g} and {epsilon / 10:g} agree); using central differences for "
            f"{', '.join(check.replaced)} (docs/drake_notes.md, AutoDiffXd derivatives of hydroelastic contact)"),
            stacklevel=3)
    return A, check
