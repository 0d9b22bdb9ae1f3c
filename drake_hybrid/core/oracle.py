"""The oracle of generated code: sympy's own evaluation of an expression at 30 significant digits.

Code that writes code is checked against what does not share its machinery. Every function that
core/symbolic.py and control/fast_law.py generate from sympy is evaluated where it is compiled, at a
sample point, and compared here with sympy's evaluation of the expression it came from
(``xreplace`` of 30-digit Floats, then ``evalf(30)``), the way a linearization checks Drake's
AutoDiffXd Jacobian against central differences: a disagreement is a ``CodeGenerationError`` naming
the function, the term, the point and both values (``check_against_sympy``).

Agreement allows only what floating point itself cannot avoid (``agrees_with_sympy``): 1e-9 of the
value, or of the magnitude of the terms a sum cancels, or what the expression's own conditioning at
the point explains. tests/test_code_generation.py checks thousands of random expression trees against
an oracle of its own.
"""

import math

import numpy as np
import sympy

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.core.errors import CodeGenerationError


def describe(expression, limit=160):
    """The expression as text for an error message, cut at ``limit`` characters."""
    text = str(expression)
    return text if len(text) <= limit else text[:limit] + " ..."


# ------------------------------------------------------------------------------------------------

ORACLE_DIGITS = 30
AGREEMENT = 1e-9           # relative to max(|value|, the magnitude bound of floating point, see _magnitude)
_SAMPLE_SCALES = (1.0, 0.5, 0.2, 0.05)
_TRIES_PER_SCALE = 4


def exact_value(expression, substitutions):
    """``expression`` at ``substitutions`` (sympy Floats of 30 digits) evaluated by sympy in 30-digit
    arithmetic, as a Python float, or None where it is not a finite real number (outside its domain, a
    pole, a complex value)."""
    try:
        result = expression.xreplace(substitutions).evalf(ORACLE_DIGITS)
    except (ArithmeticError, ValueError, TypeError, RecursionError):
        return None
    if not result.is_number or result.has(sympy.nan, sympy.zoo, sympy.oo, -sympy.oo):
        return None
    real, imaginary = result.as_real_imag()
    try:
        real, imaginary = float(real), float(imaginary)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(real) or abs(real) > 1e300 or abs(imaginary) > 1e-25 * max(1.0, abs(real)):
        return None
    return real


def _magnitude(expression):
    """The expression with every sum taken over absolute values and every factor by its absolute value:
    at a point, the scale M of the forward error bound of a floating-point evaluation (|error| <~ n eps M).
    Functions keep their value (their argument's rounding is carried by the check's second chance)."""
    if expression.is_Atom:
        return sympy.Abs(expression)
    if isinstance(expression, sympy.Add):
        return sympy.Add(*[_magnitude(term) for term in expression.args])
    if isinstance(expression, sympy.Mul):
        return sympy.Mul(*[_magnitude(factor) for factor in expression.args])
    if isinstance(expression, sympy.Pow):
        base, exponent = expression.args
        return sympy.Pow(_magnitude(base), exponent) if exponent.is_number else sympy.Abs(expression)
    return sympy.Abs(expression)


def agrees_with_sympy(expression, substitutions, computed, exact=None):
    """(agrees, exact, allowed): whether the float ``computed`` equals ``expression`` at ``substitutions``.

    Agreement is |computed - exact| <= 1e-9 max(|exact|, M), M the expression's magnitude bound
    (``_magnitude``: a sum of terms that cancel can only be computed to the size of its terms); failing
    that, within 100 times how much the exact value moves when every input moves by 1e-13 of itself (a
    point where the expression itself is ill-conditioned: a root of a sqrt, a log near 1). A generator
    defect (a lost parenthesis, a wrong constant) is wrong by the size of the value, far outside both.
    """
    if exact is None:
        exact = exact_value(expression, substitutions)
    if exact is None:
        return True, None, None
    error = abs(computed - exact) if math.isfinite(computed) else math.inf
    allowed = AGREEMENT * abs(exact)
    if error <= allowed:
        return True, exact, allowed
    magnitude = exact_value(_magnitude(expression), substitutions)
    if magnitude is not None:
        allowed = max(allowed, AGREEMENT * magnitude)
        if error <= allowed:
            return True, exact, allowed
    moved = {symbol: number * (1 + 1e-13 * (1 if i % 2 else -1))
             for i, (symbol, number) in enumerate(substitutions.items())}
    perturbed = exact_value(expression, moved)
    if perturbed is not None:
        allowed = max(allowed, AGREEMENT * abs(exact) + 100 * abs(perturbed - exact))
    return error <= allowed, exact, allowed


def sample_points(argument_sizes, seed):
    """Deterministic sample points (lists of float arrays, one per argument), at shrinking scales."""
    rng = np.random.default_rng(seed)
    for scale in _SAMPLE_SCALES:
        for _ in range(_TRIES_PER_SCALE):
            yield [scale * rng.uniform(-1.0, 1.0, size) for size in argument_sizes]


def to_autodiff(array):
    """A float array as AutoDiffXd scalars without derivatives."""
    return np.array([AutoDiffXd(float(v)) for v in array], dtype=object)


def _autodiff_values(result):
    return np.array([entry.value() if isinstance(entry, AutoDiffXd) else float(entry)
                     for entry in np.asarray(result, dtype=object).reshape(-1)])


def check_against_sympy(name, entries, argument_symbols, paths, points=1, seed=0, at=None, then=None):
    """Compare compiled functions with sympy's 30-digit evaluation of their ``entries``.

    Args:
        name: the compiled function's name, for the error.
        entries: the flat list of sympy expressions the functions compute, in order.
        argument_symbols: one tuple of symbols per argument of the functions.
        paths: {label: function}; each takes one float array per argument and returns the entries
            (any shape, flattened in order; AutoDiffXd entries are compared by value).
        points: how many sample points where every entry is a finite real number to check (one
            suffices to catch a generator defect: a wrong term agrees with the right one at a random point
            with probability zero; tests/test_code_generation.py checks thousands).
        seed: the sample points' seed (deterministic).
        at: check at this point (a list of arrays) instead of sample points.
        then: called as then(point, substitutions) at each point where every path agrees (more checks
            there, e.g. ``check_gradients``).

    Returns the number of points checked (0: no sample point lies in every entry's domain).
    Raises CodeGenerationError naming the function, the entry, the term, the point and both values.
    """
    sizes = [len(group) for group in argument_symbols]
    candidates = [at] if at is not None else sample_points(sizes, seed)
    checked = 0
    for point in candidates:
        substitutions = {symbol: sympy.Float(float(number), ORACLE_DIGITS)
                         for group, values in zip(argument_symbols, point) for symbol, number in zip(group, values)}
        exact = []
        for entry in entries:
            exact.append(exact_value(entry, substitutions))
            if exact[-1] is None:
                break                    # outside an entry's domain: another point
        if exact[-1] is None:
            continue
        computed = {}
        for label, function in paths.items():
            try:
                computed[label] = _autodiff_values(function(*point)) if label.startswith("AutoDiffXd") else \
                    np.asarray(function(*point), dtype=float).reshape(-1)
            except (ArithmeticError, ValueError):
                computed = None          # a float domain edge (e.g. sqrt of -1e-17) where sympy is exact: skip
                break
            except Exception as error:   # e.g. a TypeError: the generated code calls what the path lacks
                where = ", ".join(f"{s}={v:.6g}" for s, v in substitutions.items())
                raise CodeGenerationError(f"compiled {name} ({label}) raises {type(error).__name__} at {{{where}}}: "
                                          f"{error}") from error
        if computed is None:
            continue
        for label, values in computed.items():
            for index, (entry, value, expected) in enumerate(zip(entries, values, exact)):
                agrees, _, allowed = agrees_with_sympy(entry, substitutions, float(value), expected)
                if not agrees:
                    where = ", ".join(f"{s}={v:.6g}" for s, v in substitutions.items())
                    raise CodeGenerationError(
                        f"compiled {name} ({label}) entry {index} = {describe(entry)} gives {value!r} at "
                        f"{{{where}}}; sympy gives {expected!r} (allowed difference {allowed:.3g}): the generated "
                        "code is wrong for this term")
        if then is not None:
            then(point, substitutions)
        checked += 1
        if checked >= points:
            break
    return checked


_STEP = 1e-6               # central differences: h = _STEP max(1, |v|)
_ROUNDING = 1e3 * np.finfo(float).eps


def _differences(float_path, point, index, step):
    """(central, forward, backward, size) differences of the flattened float path along argument entry
    ``index`` (an index into the concatenated arguments; size: the largest |value| used), or None where a
    shifted point leaves the domain."""
    offsets = np.cumsum([0] + [len(a) for a in point])
    group = int(np.searchsorted(offsets, index, side="right") - 1)
    values = []
    for shift in (step, 0.0, -step):
        moved = [np.array(a, dtype=float) for a in point]
        moved[group][index - offsets[group]] += shift
        try:
            values.append(np.asarray(float_path(*moved), dtype=float).reshape(-1))
        except (ArithmeticError, ValueError):
            return None
    plus, middle, minus = values
    size = np.maximum(np.maximum(np.abs(plus), np.abs(minus)), np.abs(middle))
    return (plus - minus) / (2 * step), (plus - middle) / step, (middle - minus) / step, size


def check_gradients(name, entries, argument_symbols, float_path, autodiff_path, point, substitutions):
    """Check the AutoDiffXd path's derivatives at ``point`` (where its values agree with sympy).

    The path runs seeded with d/d(every argument entry) = I. Each derivative is compared first with the
    central difference of the float path (a cheap triage, within 1e-6 and the difference's rounding); one
    that differs is compared with sympy's derivative of the entry at 30 digits (``agrees_with_sympy``);
    where that is undefined or differs, with the one-sided differences (at a kink, |x| at 0 or a Piecewise
    on its boundary, either one-sided derivative is a right answer). Raises CodeGenerationError naming the
    function, the entry, the variable, the point and both values.
    """
    symbols = [symbol for group in argument_symbols for symbol in group]
    count = len(symbols)
    seeded, position = [], 0
    for array in point:
        seeded.append(np.array([AutoDiffXd(float(v), np.eye(count)[position + i]) for i, v in enumerate(array)],
                               dtype=object))
        position += len(array)
    try:
        result = np.asarray(autodiff_path(*seeded), dtype=object).reshape(-1)
    except (ArithmeticError, ValueError):
        return
    gradients = np.zeros((len(result), count))
    for i, entry in enumerate(result):
        if isinstance(entry, AutoDiffXd) and entry.derivatives().size:
            gradients[i] = entry.derivatives()
    for index, symbol in enumerate(symbols):
        step = _STEP * max(1.0, abs(float(substitutions[symbol])))
        differences = _differences(float_path, point, index, step)
        for entry_index, entry in enumerate(entries):
            derivative = float(gradients[entry_index, index])
            rounding = 0.0
            if differences is not None:
                central, forward, backward, size = (float(d[entry_index]) for d in differences)
                rounding = _ROUNDING * size / step
                if abs(derivative - central) <= 1e-6 * max(abs(derivative), abs(central)) + rounding:
                    continue
            agrees, exact, _ = agrees_with_sympy(sympy.diff(entry, symbol), substitutions, derivative)
            if agrees and exact is not None:
                continue
            if differences is not None and \
                    min(abs(derivative - forward), abs(derivative - backward)) <= 1e-4 * max(1.0, abs(derivative)) + \
                    rounding:
                continue
            if exact is None and differences is None:
                continue                 # nothing defined to compare with
            where = ", ".join(f"{s}={v:.6g}" for s, v in substitutions.items())
            source, expected = ("sympy", exact) if exact is not None else ("central differences", central)
            raise CodeGenerationError(
                f"compiled {name} (AutoDiffXd) d(entry {entry_index} = {describe(entry)})/d{symbol} gives "
                f"{derivative!r} at {{{where}}}; {source} gives {expected!r}: the generated derivative is wrong "
                "for this term")
