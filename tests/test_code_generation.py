"""The code generator (core/symbolic.py, control/fast_law.py) against an oracle that shares none of it.

Random expression trees are written as text in the task files' grammar (core/expressions.py). The
package's path: the text is parsed by the grammar into sympy, made a ``Constraint`` (which derives
E_f and E_f-dot nu symbolically and compiles them for float and AutoDiffXd), and the same terms are
compiled by numba through control/fast_law.py's generated module. The oracle: the text parsed by
sympy's own parser, differentiated by sympy in this file, and evaluated by ``evalf(30, subs=...)``.

Agreement is 1e-9 relative at every point where a double-precision evaluation of the expression can
reach it at all: a point where sympy's tree evaluated in 53-bit arithmetic (mpmath, sympy's own
printer) is already more than 1e-11 off the 30-digit value is ill-conditioned for any floating-point
code (a cancellation, the edge of a domain) and is skipped; tests count the skips and keep them rare.
The compile-time check of core/symbolic.py is switched off here, so that what is tested is the
generated code itself, against an oracle written here; the check's own test breaks the printer.
"""

import math

import mpmath
import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.control import fast_law
from drake_hybrid.core import symbolic
from drake_hybrid.core.charts import PlanarChart, PoseChart
from drake_hybrid.core.constraints import Constraint
from drake_hybrid.core.errors import CodeGenerationError, ConfigError, ExpressionError
from drake_hybrid.core.expressions import expression_to_sympy

# Random trees have poles and domain edges: numpy's division warnings there are expected.
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

CHART = PlanarChart()
X_SYMBOLS = CHART.configuration_symbols
NU_SYMBOLS = CHART.velocity_symbols
ORACLE_LOCALS = {str(s): s for s in X_SYMBOLS} | {"abs": sympy.Abs, "pi": sympy.pi}
UNARY = ["sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "sqrt", "exp", "log", "abs"]
EXPONENTS = ["2", "3", "4", "5", "-1", "-2", "-3", "(1/2)", "(1/3)", "(3/2)", "(-1/2)", "0.7"]
RELATIVE = 1e-9
CONDITIONING = 1e-11

leaves = st.sampled_from(["x", "y", "theta", "1", "2", "3", "0.5", "1.25", "7", "pi"])
trees = st.recursive(
    leaves,
    lambda children: st.one_of(
        st.tuples(st.sampled_from(UNARY), children).map(lambda t: f"{t[0]}({t[1]})"),
        st.tuples(children, st.sampled_from(["+", "-", "*", "/"]), children).map(lambda t: f"({t[0]} {t[1]} {t[2]})"),
        st.tuples(children, st.sampled_from(EXPONENTS)).map(lambda t: f"({t[0]})**{t[1]}"),
        st.tuples(children, st.sampled_from(["x", "y", "theta", "2"])).map(lambda t: f"({t[1]})**({t[0]})"),
        st.tuples(children, children).map(lambda t: f"atan2({t[0]}, {t[1]})"),
    ),
    max_leaves=7)
# Coordinates of a robot's size, 1e-4 to 1 in magnitude: no subnormal inputs (doubles underflow where
# sympy's arithmetic does not) and no exact zero (where a composition such as (x**pi)**0.7 has an
# infinite inner derivative, the chain rule of any AutoDiff gives 0 * inf); neither says anything
# about the generated code.
coordinate = st.builds(lambda sign, magnitude: sign * magnitude, st.sampled_from([-1.0, 1.0]), st.floats(1e-4, 1.0))
coordinates = st.lists(coordinate, min_size=6, max_size=6)


@pytest.fixture(autouse=True)
def generated_code_only(monkeypatch):
    """The compiled code alone: the compile-time check (tested below) is off."""
    monkeypatch.setattr(symbolic, "check_against_sympy", lambda *arguments, **keywords: 1)


# ------------------------------------------------------------------------------------------------
# The oracle
# ------------------------------------------------------------------------------------------------

class Oracle:
    """Every term of one text by sympy alone (PlanarChart: L = I, so E_f = dC/dx and E_f-dot nu =
    nu^T H nu with H = d^2 C / dx^2), evaluated at 30 digits.

    ``entries``: C, E_f (3), E_f-dot nu, then what the AutoDiffXd gradients must equal: H's six
    distinct entries (d E_f / dx) and d(E_f-dot nu)/d nu = 2 H nu (3)."""

    PAIRS = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]

    def __init__(self, text):
        C = sympy.sympify(text, locals=ORACLE_LOCALS)
        nu = sympy.Matrix(NU_SYMBOLS)
        H = sympy.hessian(C, X_SYMBOLS)
        E_f = [sympy.diff(C, s) for s in X_SYMBOLS]
        self.entries = [C, *E_f, (nu.T * H * nu)[0], *[H[i, j] for i, j in self.PAIRS], *(2 * H * nu)]
        self.symbols = list(X_SYMBOLS) + list(NU_SYMBOLS)
        modules = [{"DiracDelta": lambda *a: mpmath.mpf(0), "sign": mpmath.sign, "Abs": abs}, "mpmath"]
        self._in_doubles = [self._lambdify(entry, modules) for entry in self.entries]
        # C's sub-terms that can leave the reals (sqrt(x) at x < 0): a real path is undefined wherever one
        # does, even if sympy's whole value is real (atan2 of two imaginary numbers)
        self._subterms = [term for term in sympy.preorder_traversal(C)
                          if term.free_symbols and isinstance(term, (sympy.Function, sympy.Pow))]

    def _lambdify(self, entry, modules):
        try:
            return sympy.lambdify(self.symbols, entry, modules=modules)
        except ValueError:        # sympy's printer refuses e.g. Derivative(sign(x**x), x): the term is skipped
            return None

    def _exact(self, expression, substitutions, strict=False):
        """The 30-digit real value, or None where it is not a finite real number: an imaginary part
        above 1e-25 of max(1, |real|) (an entry: sympy's noise from complex intermediates), or
        ``strict``, of the value's own size (a sub-term: (-1e-4)**11.5 is complex, however small)."""
        try:
            value = sympy.N(expression, 30, subs=substitutions)
        except (ArithmeticError, ValueError, TypeError):
            return None
        if not value.is_number or value.has(sympy.nan, sympy.zoo, sympy.oo, -sympy.oo):
            return None
        real, imaginary = (float(part) for part in value.as_real_imag())
        scale = math.hypot(real, imaginary) if strict else max(1.0, abs(real))
        if not math.isfinite(real) or abs(real) > 1e250 or abs(imaginary) > 1e-25 * scale:
            return None
        return real

    def _real_everywhere(self, substitutions):
        return all(self._exact(term, substitutions, strict=True) is not None for term in self._subterms)

    def values(self, point):
        """The 30-digit value of each entry, or None where it is undefined or where 53-bit arithmetic on
        sympy's own tree is more than 1e-11 off (ill-conditioned for any floating-point code); and
        whether each is defined at all (a finite real number, with every sub-term of C real)."""
        substitutions = {s: sympy.Float(float(v), 30) for s, v in zip(self.symbols, point)}
        arguments = [mpmath.mpf(float(v)) for v in point]
        doubles = []
        with mpmath.workprec(53):
            for function in self._in_doubles:
                try:
                    doubles.append(None if function is None else complex(function(*arguments)))
                except Exception:          # mpmath on a complex intermediate (atan2 of a complex): undefined
                    doubles.append(None)
        values, defined = [], []
        real_everywhere = self._real_everywhere(substitutions)
        for expression, double in zip(self.entries, doubles):
            exact = self._exact(expression, substitutions) if real_everywhere else None
            defined.append(exact is not None)
            if exact is None or double is None or double.imag != 0 or \
                    abs(double.real - exact) > CONDITIONING * abs(exact):
                exact = None
            values.append(exact)
        return values, defined


def agree(computed, exact):
    return abs(computed - exact) <= RELATIVE * abs(exact)


def compiled_terms(constraint, point):
    x, nu = np.array(point[:3]), np.array(point[3:])
    return np.concatenate([constraint.value(x), constraint.force_projection(x).reshape(-1),
                           constraint.curvature(x, nu)])


def autodiff_terms(constraint, point):
    """(values, gradients) of the AutoDiffXd path, seeded with d/d(x, nu) = I (gradients: 5 x 6)."""
    seeded = [AutoDiffXd(v, np.eye(6)[i]) for i, v in enumerate(point)]
    x, nu = np.array(seeded[:3], dtype=object), np.array(seeded[3:], dtype=object)
    entries = np.concatenate([constraint.value(x), constraint.force_projection(x).reshape(-1),
                              constraint.curvature(x, nu)])
    values = np.array([e.value() if isinstance(e, AutoDiffXd) else float(e) for e in entries])
    gradients = np.array([e.derivatives() if isinstance(e, AutoDiffXd) and e.derivatives().size else np.zeros(6)
                          for e in entries])
    return values, gradients


class Tally:
    """How many terms were compared and how many skipped (outside a domain, ill-conditioned)."""

    def __init__(self):
        self.compared, self.skipped, self.trees = 0, 0, 0


def package_constraint(text):
    """The package's path: the grammar's parse of ``text``, made a Constraint (compiled)."""
    return Constraint(CHART, [expression_to_sympy(text, X_SYMBOLS, where="tree")], name=text[:40])


def check_tree(text, constraint, point, tally, numba_values=None):
    """Every compiled path's C, E_f, E_f-dot nu (and the AutoDiffXd gradients) against the oracle."""
    oracle = Oracle(text)
    exact, defined = oracle.values(point)
    tally.trees += 1
    try:
        float_values = compiled_terms(constraint, point)
        autodiff_values, gradients = autodiff_terms(constraint, point)
    except (ValueError, ArithmeticError):
        # math's domain error: only where a term is undefined (each function computes its terms together)
        assert not all(defined[:5]), f"{text}: the float path raised at {point} where sympy defines every term"
        tally.skipped += 5
        return
    # the gradients the AutoDiffXd path must give: (term, column) -> the oracle's entry
    expected_gradients = {(0, j): 1 + j for j in range(3)}
    for k, (i, j) in enumerate(Oracle.PAIRS):
        expected_gradients[(1 + i, j)] = expected_gradients[(1 + j, i)] = 5 + k
    expected_gradients |= {(4, 3 + j): 11 + j for j in range(3)}
    for index in range(5):
        if exact[index] is None:
            tally.skipped += 1
            continue
        tally.compared += 1
        for label, values in (("float", float_values), ("AutoDiffXd", autodiff_values), ("numba", numba_values)):
            if values is not None:
                assert agree(values[index], exact[index]), (text, point, index, label, values[index], exact[index])
    for (index, column), entry in expected_gradients.items():
        if exact[entry] is not None and exact[index] is not None:
            assert agree(gradients[index, column], exact[entry]), \
                (text, point, index, f"d/d{oracle.symbols[column]}", gradients[index, column], exact[entry])


def numba_batch(constraints, points):
    """The constraints' terms through control/fast_law.py's generated module (C column, E_f matrix, E_f-dot
    nu column: the production layout), compiled by numba; one row of values per constraint."""
    terms = [sympy.Matrix([c.symbolic_terms[0][0] for c in constraints]),
             sympy.Matrix.vstack(*[c.symbolic_terms[1] for c in constraints]),
             sympy.Matrix([c.symbolic_terms[2][0] for c in constraints])]
    module = fast_law.load_generated(fast_law.MODULE_HEADER + fast_law._piece_source("_terms_0", terms, CHART))
    rows = []
    for index, point in enumerate(points):
        # one evaluation per tree at its own point: the module computes every tree, we keep tree `index`
        try:
            C, E_f, curvature = module._terms_0(np.array(point[:3]), np.array(point[3:]))
        except ZeroDivisionError:        # another tree's pole at this point (numba raises as Python does)
            rows.append(None)
            continue
        rows.append(np.concatenate([[C[index]], E_f[index], [curvature[index]]]))
    return rows


def run_batches(texts_and_points):
    tally = Tally()
    texts = [text for text, _ in texts_and_points]
    points = [point for _, point in texts_and_points]
    constraints = [package_constraint(text) for text in texts]
    numba_rows = numba_batch(constraints, points)
    for text, constraint, point, row in zip(texts, constraints, points, numba_rows):
        check_tree(text, constraint, point, tally, row)
    return tally


def compilable(text):
    try:
        symbolic.prepare_expression(expression_to_sympy(text, X_SYMBOLS, where="tree"))
    except (ExpressionError, ConfigError):
        return False       # a complex constant such as asin(7), an exponent the grammar refuses: tested elsewhere
    return True


batches = st.lists(st.tuples(trees.filter(compilable), coordinates), min_size=40, max_size=40)
# No shrinking: a batch of 40 trees shrinks for minutes, and every assertion names its tree and point.
SETTINGS = dict(deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate], suppress_health_check=[HealthCheck.too_slow,
                                                                         HealthCheck.function_scoped_fixture,
                                                                         HealthCheck.filter_too_much,
                                                                         HealthCheck.data_too_large])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DRAKE_HYBRID_CACHE", str(tmp_path))


def _property(batch):
    tally = run_batches(batch)
    # skipped: points outside a tree's domain or ill-conditioned for doubles; the rest were compared
    assert tally.compared >= 2 * len(batch), f"only {tally.compared} entries compared in {len(batch)} trees"


@settings(max_examples=3, **SETTINGS)
@given(batch=batches)
def test_generated_code_equals_sympy_quick(batch, cache):
    """120 trees: the fast loop's share of the property below."""
    _property(batch)


@pytest.mark.slow
@settings(max_examples=25, **SETTINGS)
@given(batch=batches)
def test_generated_code_equals_sympy(batch, cache):
    """1,000 random expression trees (25 batches of 40): C, E_f and E_f-dot nu from the float, AutoDiffXd
    (values and gradients) and numba paths, each within 1e-9 of sympy's 30-digit value."""
    _property(batch)


# ------------------------------------------------------------------------------------------------
# The cases that were wrong, and what is refused
# ------------------------------------------------------------------------------------------------

def test_power_in_a_denominator():
    """Issue 30's constraint: y - 1/(1 + x^2) gave E_f = [0.6, 1, 0] and curvature 1.339."""
    x, y, _ = X_SYMBOLS
    constraint = Constraint(CHART, [y - 1 / (1 + x**2)])
    point = [0.3, 0.0, 0.0]
    exact_gradient = float(sympy.diff(2 * x / (1 + x**2)**2, x).subs(x, 0.3))        # d^2 C / dx^2 = -(...)
    assert constraint.force_projection(point)[0, 0] == pytest.approx(2 * 0.3 / 1.09**2, rel=1e-14)
    assert constraint.curvature(point, [1.0, 0.0, 0.0])[0] == pytest.approx(exact_gradient, rel=1e-14)
    assert constraint.force_projection(point)[0, 0] == pytest.approx(0.505008, abs=1e-6)
    assert constraint.curvature(point, [1.0, 0.0, 0.0])[0] == pytest.approx(1.127388, abs=1e-6)


@pytest.mark.parametrize("expression, value", [
    (sympy.E * sympy.Symbol("x", real=True), math.e * 0.3),
    (sympy.Rational(1, 3) * sympy.Symbol("x", real=True)**5, 0.3**5 / 3),
    (2**sympy.Symbol("x", real=True), 2**0.3),
    (sympy.Integer(2)**70 * sympy.Symbol("x", real=True), 2.0**70 * 0.3),
    (sympy.sec(sympy.Symbol("x", real=True)), 1 / math.cos(0.3)),
    (sympy.asinh(sympy.Symbol("x", real=True)), math.asinh(0.3)),
    (sympy.Max(sympy.Symbol("x", real=True), 0)**3, 0.027),
    (sympy.Abs(sympy.Symbol("x", real=True) - 1), 0.7),
])
def test_constants_and_functions_every_path_evaluates(expression, value):
    x = X_SYMBOLS[0]
    expression = expression.xreplace({sympy.Symbol("x", real=True): x})
    constraint = Constraint(CHART, [X_SYMBOLS[1] - expression])
    point = np.array([0.3, 0.0, 0.0])
    assert constraint.value(point)[0] == pytest.approx(-value, rel=1e-13)
    seeded = np.array([AutoDiffXd(v, np.eye(3)[i]) for i, v in enumerate(point)], dtype=object)
    assert constraint.value(seeded)[0].value() == pytest.approx(-value, rel=1e-13)
    derivative = float(sympy.N(sympy.diff(-expression, x).subs(x, sympy.Float(0.3, 30)), 30))
    assert constraint.force_projection(point)[0, 0] == pytest.approx(derivative, rel=1e-12)
    assert constraint.value(seeded)[0].derivatives()[0] == pytest.approx(derivative, rel=1e-12)


@pytest.mark.parametrize("constant, words", [
    (sympy.nan, "nan"), (sympy.oo, "infinity"), (sympy.zoo, "zoo"), (sympy.I, "imaginary unit"),
    (sympy.Float("inf"), "infinity"), (sympy.acos(sympy.pi), "acos.pi. is not a finite real number"),
    (sympy.asin(7) * X_SYMBOLS[0], "asin.7. is not a finite real number"),
])
def test_refused_constants(constant, words):
    _, y, _ = X_SYMBOLS
    with pytest.raises(ExpressionError, match=words):
        Constraint(CHART, [y - constant], name="bad")


@pytest.mark.parametrize("function", [sympy.floor, sympy.gamma, sympy.erf, sympy.Function("f")])
def test_refused_functions(function):
    x, y, _ = X_SYMBOLS
    with pytest.raises(ExpressionError, match="cannot be compiled; allowed: sin, cos"):
        Constraint(CHART, [y - function(x)], name="bad")


def test_refused_non_expression():
    with pytest.raises(ExpressionError, match="is not an expression"):
        Constraint(CHART, ["y - x"], name="text")


def test_compile_time_check_names_the_term(monkeypatch):
    """The check in core/symbolic.py catches a broken printer (the old one: no parentheses around a power
    printed as a product) and names the term."""
    monkeypatch.undo()                     # the real check
    original = symbolic._Printer._print_Pow

    def without_parentheses(printer, expression, rational=False):
        text = original(printer, expression, rational)
        return text[1:-1] if text.startswith("((") and text.endswith("))") else text

    monkeypatch.setattr(symbolic._Printer, "_print_Pow", without_parentheses)
    x, y, _ = X_SYMBOLS
    with pytest.raises(CodeGenerationError, match=r"E_f\[denominator\] \(float\) entry 0 = .*x\*\*2 \+ 1"):
        Constraint(CHART, [y - 1 / (1 + x**2)], name="denominator")


def test_compile_time_check_on_first_call_outside_samples(monkeypatch):
    """A function defined nowhere near the sample points is checked at its first float call."""
    monkeypatch.undo()
    x, y, _ = X_SYMBOLS
    constraint = Constraint(CHART, [y - sympy.sqrt(x - 5) * sympy.log(x - 5)], name="far")
    assert constraint._value.checked_points == 0
    constraint.value([6.5, 0.0, 0.0])
    assert constraint._value.checked_points == 1


def test_pose_chart_terms_against_sympy(monkeypatch):
    """The chart map L(x) of PoseChart (x-dot = L nu for the entries of R): the compile-time check of
    every term of an ellipsoid's constraint passes and E_f-dot nu equals the oracle's."""
    monkeypatch.undo()
    chart = PoseChart()
    p = chart.position
    f = p[0]**2 / sympy.Rational(9, 100) + p[1]**2 / sympy.Rational(4, 100) + p[2]**2 / sympy.Rational(1, 100) - 1
    constraint = Constraint(chart, [f, sympy.Matrix(chart.rotation[:, 0]).dot(sympy.Matrix([f.diff(s) for s in p]))])
    assert all(function.checked_points == 1 for function in
               (constraint._value, constraint._force_projection, constraint._curvature))
    rng = np.random.default_rng(3)
    x, nu = rng.uniform(-1, 1, 12), rng.uniform(-1, 1, 6)
    substitutions = {s: sympy.Float(float(v), 30) for s, v in zip(chart.configuration_symbols, x)}
    substitutions |= {s: sympy.Float(float(v), 30) for s, v in zip(chart.velocity_symbols, nu)}
    C = sympy.Matrix(constraint.expressions)
    C_dot = C.jacobian(chart.configuration_symbols) * chart.configuration_rate
    curvature = C_dot.jacobian(chart.configuration_symbols) * chart.configuration_rate
    for computed, expected in zip(constraint.curvature(x, nu), curvature):
        assert computed == pytest.approx(float(sympy.N(expected, 30, subs=substitutions)), rel=1e-9)
