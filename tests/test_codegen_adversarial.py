"""The code generator (core/symbolic.py) and the task files' grammar (core/expressions.py) on adversarial
input: constants beyond the float range, Unicode and keyword names, sympy nodes that are not functions,
the inverse hyperbolic functions where their log forms cancel, coordinate names that are not Python
identifiers, and pydrake.symbolic variables matched by name. Every compiled value is compared with an
oracle of this file (Python's exact rational arithmetic, math's and mpmath's functions, sympy's evalf);
every refusal is a one-line typed error naming the field or the term.
"""

import keyword
import math
import re
import unicodedata
from fractions import Fraction

import mpmath
import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import pydrake.symbolic as drake_symbolic
from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.control import fast_law
from drake_hybrid.core import symbolic
from drake_hybrid.core.charts import Chart, PlanarChart
from drake_hybrid.core.constraints import Constraint
from drake_hybrid.core.errors import CodeGenerationError, ConfigError, ExpressionError, UnknownVariableError
from drake_hybrid.core.expressions import check_parameter_names, expression_to_sympy

CHART = PlanarChart()
X, Y, THETA = CHART.configuration_symbols
WHERE = "task.yaml: constraint.rows[0]"
SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def seeded(point):
    """``point`` as AutoDiffXd with d/d(point) = I."""
    return np.array([AutoDiffXd(float(v), np.eye(len(point))[i]) for i, v in enumerate(point)], dtype=object)


def chart_of(names):
    """A three-coordinate chart (L = I) whose coordinates are called ``names``."""
    chart = Chart()
    chart.configuration_symbols = tuple(sympy.Symbol(name, real=True) for name in names)
    chart.velocity_symbols = tuple(sympy.Symbol(f"v{i}", real=True) for i in range(len(names)))
    chart.configuration_rate = sympy.Matrix(chart.velocity_symbols)
    return chart


# ------------------------------------------------------------------------------------------------
# D1: integer and rational constants beyond the float range
# ------------------------------------------------------------------------------------------------

big_integers = st.integers(2**31, 10**300) | st.integers(-10**300, -2**31)
fractions = st.tuples(st.integers(-10**400, 10**400), st.integers(1, 10**400)).filter(
    lambda pq: pq[0] != 0 and Fraction(1, 10**250) < abs(Fraction(*pq)) < 10**250)


@settings(max_examples=20, **SETTINGS)
@given(coefficient=big_integers | fractions.map(lambda pq: Fraction(*pq)))
def test_big_constants_print_as_their_float(coefficient):
    """C = c x + y with c an integer or a rational of up to 400 digits (finite as a float): the float and
    AutoDiffXd paths give float(c) x + y, the derivative dC/dx = float(c) (Python's exact arithmetic)."""
    c = sympy.Integer(coefficient) if isinstance(coefficient, int) else sympy.Rational(coefficient.numerator,
                                                                                        coefficient.denominator)
    constraint = Constraint(CHART, [c * X + Y], name="big")
    expected = float(Fraction(coefficient))
    point = np.array([0.375, 0.5, 0.0])
    assert constraint.value(point)[0] == pytest.approx(expected * 0.375 + 0.5, rel=1e-15, abs=1e-300)
    assert constraint.force_projection(point)[0, 0] == expected
    value = constraint.value(seeded(point))[0]
    assert value.value() == pytest.approx(expected * 0.375 + 0.5, rel=1e-15, abs=1e-300)
    assert value.derivatives()[0] == expected


@pytest.mark.parametrize("constant", [sympy.Integer(10)**309, -sympy.Integer(10)**400,
                                      sympy.Rational(10**700 + 1, 10**300), sympy.Float("1e400")])
def test_constants_beyond_the_float_range_are_refused(constant):
    with pytest.raises(ExpressionError, match=r"constraint 'huge': the constant .* beyond the float range"):
        Constraint(CHART, [constant * X + Y], name="huge")


@pytest.mark.parametrize("text", ["y*10**100*10**100*10**100*10**10 - x", "y*1e200*1e200 - x",
                                  "x / (1e-200 * 1e-200)", "10**90 * 10**90 * 10**90 * 10**90 * x"])
def test_task_file_constants_beyond_1e300_are_refused(text):
    with pytest.raises(ConfigError, match=rf"^{re.escape(WHERE)}: a constant beyond 1e300"):
        expression_to_sympy(text, CHART.configuration_symbols, {}, where=WHERE)


# ------------------------------------------------------------------------------------------------
# D2: parameter names as the parser reads them (NFKC), keywords
# ------------------------------------------------------------------------------------------------

def _read(name):
    return unicodedata.normalize("NFKC", name)


# Characters Python's parser reads as another identifier: ℌ -> H, µ (micro) -> μ, ﬁ -> fi, ｘ -> x.
compatibility_letters = st.characters(min_codepoint=0xA0, max_codepoint=0x1FFFF).filter(
    lambda c: c.isidentifier() and _read(c) != c and _read(c).isidentifier() and not _read(c).startswith("_")
    and not keyword.iskeyword(_read(c)) and _read(c) not in ("x", "y", "theta", "pi", "E") and
    not _read(c).startswith(("sin", "cos", "tan", "a", "sqrt", "exp", "log", "abs")))


@settings(max_examples=40, **SETTINGS)
@given(letter=compatibility_letters, value=st.floats(-10, 10, allow_nan=False))
def test_a_parameter_is_found_by_the_name_the_parser_reads(letter, value):
    """A parameter spelled with a compatibility character is found whether the row spells it so or in its
    normalized form; one that collides with another parameter after normalization is refused, naming both."""
    parameters = {letter: value}
    check_parameter_names(parameters, CHART.configuration_symbols, "task.yaml: parameters")
    for spelling in (letter, _read(letter)):
        expression = expression_to_sympy(f"y - {spelling}", CHART.configuration_symbols, parameters, where=WHERE)
        assert expression == Y - sympy.Float(value)
    with pytest.raises(ConfigError, match=rf"task.yaml: parameters: the parameters '{_read(letter)}' and '{letter}'"):
        check_parameter_names({_read(letter): 1.0, letter: value}, CHART.configuration_symbols, "task.yaml: parameters")


@pytest.mark.parametrize("name", [k for k in keyword.kwlist if k not in ("True", "False", "None")])
def test_keyword_parameter_names_are_refused(name):
    with pytest.raises(ConfigError, match=rf"task.yaml: parameters: .*keyword, got '{name}'"):
        check_parameter_names({name: 1.0}, CHART.configuration_symbols, "task.yaml: parameters")


@pytest.mark.parametrize("name", ["ｘ", "ｐｉ", "ｓｉｎ"])
def test_parameter_names_that_read_as_a_coordinate_function_or_constant_are_refused(name):
    with pytest.raises(ConfigError, match=rf"task.yaml: parameters.{name}: the name is taken"):
        check_parameter_names({name: 1.0}, CHART.configuration_symbols, "task.yaml: parameters")


# ------------------------------------------------------------------------------------------------
# D3: sympy nodes no path evaluates, and rows that are not expressions
# ------------------------------------------------------------------------------------------------

K = sympy.Symbol("k", integer=True)


@pytest.mark.parametrize("expression, term", [
    (sympy.Product(X + K, (K, 1, 3)) + Y, "Product"),
    (sympy.Sum(X**K, (K, 0, 3)) + Y, "Sum"),
    (sympy.O(X**3) + Y, "Order"),
    (sympy.AccumBounds(-1, 1) + X, "AccumulationBounds"),
    (sympy.Piecewise((X, sympy.Contains(X, sympy.Interval(0, 1))), (0, True)) + Y, "Contains"),
    (sympy.Integral(X * THETA, (THETA, 0, 1)) + Y, "Integral"),
    (sympy.floor(X) + Y, "floor"),
    (sympy.Function("f")(X) + Y, "f"),
    (sympy.Derivative(sympy.Function("g")(X), X) + Y, "Derivative"),
    (sympy.Mod(X, 1) + Y, "Mod"),
])
def test_nodes_no_path_evaluates_are_refused(expression, term):
    with pytest.raises(ExpressionError, match=rf"^constraint 'bad': the (function|term) {term} in .* cannot be "
                                              "compiled; allowed: sin, cos"):
        Constraint(CHART, [expression], name="bad")


@pytest.mark.parametrize("row, kind", [
    (X > 0, "StrictGreaterThan"), (sympy.Eq(X, Y), "Equality"), (sympy.And(X > 0, Y < 1), "And"),
    (sympy.true, "BooleanTrue"), (sympy.Poly(X**2 + 1, X), "Poly"), (sympy.Interval(0, 1), "Interval"),
    (drake_symbolic.Variable("x") > 0, "StrictGreaterThan"),
])
def test_rows_that_are_not_expressions_are_refused(row, kind):
    with pytest.raises(ExpressionError, match=rf"^constraint 'bad': .*\(a {kind}\) is not an expression"):
        Constraint(CHART, [row], name="bad")


def test_max_min_heaviside_are_rewritten_before_differentiation():
    """Max, Min and Heaviside are not sympy Functions: their rewrites run (into Piecewise)."""
    expression = symbolic.prepare_expression(sympy.Max(X, Y) + sympy.Min(X, THETA) + sympy.Heaviside(Y) * X)
    assert not expression.has(sympy.Max, sympy.Min, sympy.Heaviside) and expression.has(sympy.Piecewise)
    constraint = Constraint(CHART, [sympy.Max(X, Y) + sympy.Min(X**2, THETA) - 1], name="lattice")
    point = np.array([0.3, -0.2, 0.5])
    assert constraint.value(point)[0] == pytest.approx(0.3 + 0.09 - 1, rel=1e-15)
    assert list(constraint.force_projection(point)[0]) == pytest.approx([1.0 + 0.6, 0.0, 0.0], rel=1e-15)


# ------------------------------------------------------------------------------------------------
# D4: asinh, acosh, atanh to full accuracy on every path
# ------------------------------------------------------------------------------------------------

INVERSE_HYPERBOLIC = [  # (sympy function, mpmath function, the argument u = a x + b)
    (sympy.asinh, mpmath.asinh, st.floats(-1e8, 1e8), st.floats(-1e3, 1e3)),
    (sympy.atanh, mpmath.atanh, st.floats(-1, 1), st.floats(-0.5, 0.5)),
    (sympy.acosh, mpmath.acosh, st.floats(0, 1e6), st.floats(1.0, 1e3)),
]


@settings(max_examples=15, **SETTINGS)
@given(data=st.data(), which=st.sampled_from(range(3)), x=st.floats(1e-15, 0.5) | st.floats(-0.5, -1e-15))
def test_inverse_hyperbolic_functions_are_accurate(data, which, x):
    """C = f(a x + b) - y with u = a x + b anywhere in f's domain (asinh at large |u|, atanh and asinh at
    u -> 0, where C = 0): the float and AutoDiffXd values within 4 ulp of mpmath's, dC/dx = a f'(u)."""
    function, exact, scales, offsets = INVERSE_HYPERBOLIC[which]
    a, b = data.draw(scales), data.draw(offsets)
    u = a * x + b
    if which == 1 and not abs(u) < 0.999 or which == 2 and not u > 1.001 or u == 0:
        return
    constraint = Constraint(CHART, [function(sympy.Float(a) * X + sympy.Float(b)) - Y], name="hyperbolic")
    point = np.array([x, 0.0, 0.0])
    with mpmath.workdps(40):
        argument = mpmath.mpf(a) * mpmath.mpf(x) + mpmath.mpf(b)      # the argument at 40 digits
        value = float(exact(argument))
        derivative = float(a * mpmath.diff(exact, argument))
    # the float argument a x + b is rounded once: its relative error propagates with f's conditioning
    conditioning = abs(float(argument) * float(mpmath.diff(exact, argument)) / value) if value else 1.0
    tolerance = 4 * np.finfo(float).eps * abs(value) * max(1.0, conditioning) * (1 + abs(a * x) / abs(u))
    assert abs(constraint.value(point)[0] - value) <= tolerance
    autodiff = constraint.value(seeded(point))[0]
    assert abs(autodiff.value() - value) <= tolerance
    assert autodiff.derivatives()[0] == pytest.approx(derivative, rel=1e-12)


def test_inverse_hyperbolic_functions_near_zero_of_c_on_every_path(tmp_path, monkeypatch):
    """The review's cases: asinh(y - 0.98) at y = 0.98 + 1e-12 and atanh(x) at x = 1e-12 (the log forms were
    1e-4 off), asinh(1e8 x) at x < 0 (refused as wrong code), on the float, AutoDiffXd and numba paths."""
    monkeypatch.setenv("DRAKE_HYBRID_CACHE", str(tmp_path))
    rows = [sympy.asinh(Y - sympy.Float(0.98)), sympy.atanh(X), sympy.asinh(sympy.Float(1e8) * X) + THETA,
            sympy.acosh(2 + X**2)]
    constraints = [Constraint(CHART, [row], name=f"row {i}") for i, row in enumerate(rows)]
    point = np.array([-1e-12, 0.98 + 1e-12, 0.0])
    expected = [math.asinh(point[1] - 0.98), math.atanh(point[0]), math.asinh(1e8 * point[0]),
                math.acosh(2 + point[0]**2)]
    terms = [sympy.Matrix([c.symbolic_terms[0][0] for c in constraints]),
             sympy.Matrix.vstack(*[c.symbolic_terms[1] for c in constraints]),
             sympy.Matrix([c.symbolic_terms[2][0] for c in constraints])]
    module = fast_law.load_generated(fast_law.MODULE_HEADER + fast_law._piece_source("_terms_0", terms, CHART))
    numba_values = module._terms_0(point, np.zeros(3))[0]
    for constraint, value, numba_value in zip(constraints, expected, numba_values):
        assert constraint.value(point)[0] == pytest.approx(value, rel=1e-15)
        assert constraint.value(seeded(point))[0].value() == pytest.approx(value, rel=1e-15)
        assert numba_value == pytest.approx(value, rel=1e-15)


# ------------------------------------------------------------------------------------------------
# D5: coordinate names that are not identifiers, or are the generated code's own names
# ------------------------------------------------------------------------------------------------

# Names of the generated code (namespaces, arguments, CSE temporaries), keywords, and non-identifiers.
ADVERSARIAL_NAMES = ["pi", "E", "sqrt", "abs", "exp", "pow", "log", "_sign", "_array", "_shape", "_dtype", "_arg0",
                     "_t0", "_t1", "_s0", "_s1", "_compiled_0", "if", "lambda", "None", "x y", "x₁", "ℌ", "H", "1x",
                     "a-b", "np", "math", "sin"]
names = st.lists(st.sampled_from(ADVERSARIAL_NAMES) | st.text(min_size=1, max_size=4), min_size=3, max_size=3,
                 unique=True)


@settings(max_examples=25, **SETTINGS)
@given(chosen=names, point=st.lists(st.floats(0.1, 0.9), min_size=3, max_size=3))
def test_any_coordinate_names_compile(chosen, point):
    """C = a b + sqrt(c^2 + 1) pi - exp(a) with coordinates named anything (spaces, subscripts, 'pi',
    '_t0', 'sqrt', a keyword, names equal after NFKC): float and AutoDiffXd values and gradient equal the
    oracle's (sympy at 30 digits of the same expression)."""
    chart = chart_of(chosen)
    a, b, c = chart.configuration_symbols
    expression = a * b + sympy.sqrt(c**2 + 1) * sympy.pi - sympy.exp(a) + sympy.asinh(b)
    constraint = Constraint(chart, [expression], name="names")
    substitutions = {s: sympy.Float(v, 30) for s, v in zip((a, b, c), point)}
    value = float(expression.evalf(30, subs=substitutions))
    gradient = [float(expression.diff(s).evalf(30, subs=substitutions)) for s in (a, b, c)]
    assert constraint.value(np.array(point))[0] == pytest.approx(value, rel=1e-14)
    assert list(constraint.force_projection(np.array(point))[0]) == pytest.approx(gradient, rel=1e-14)
    autodiff = constraint.value(seeded(point))[0]
    assert autodiff.value() == pytest.approx(value, rel=1e-14)
    assert list(autodiff.derivatives()) == pytest.approx(gradient, rel=1e-14)


def test_generated_code_holds_no_user_name():
    """Every symbol is printed by a generated name (_s<k>), every CSE temporary as _t<k>."""
    chart = chart_of(["x y", "pi", "_t0"])
    a, b, c = chart.configuration_symbols
    assignments, results, printer = symbolic.straight_line_program([sympy.sin(a * b) + sympy.sin(a * b)**2 + c])
    code = " ".join([target + " = " + text for target, text in assignments] + results)
    printed = [printer.doprint(s) for s in (a, b, c)]
    assert sorted(printed) == ["_s0", "_s1", "_s2"]
    assert "x y" not in code and "pi" not in code and [target for target, _ in assignments] == ["_t0"]


def test_numba_path_with_adversarial_names(tmp_path, monkeypatch):
    """The numba module of control/fast_law.py binds its arguments by the generated names too."""
    monkeypatch.setenv("DRAKE_HYBRID_CACHE", str(tmp_path))
    chart = chart_of(["pi", "x y", "_t0"])
    a, b, c = chart.configuration_symbols
    constraint = Constraint(chart, [a * sympy.pi + sympy.sqrt(b**2 + 1) - sympy.exp(c)], name="names")
    module = fast_law.load_generated(fast_law.MODULE_HEADER +
                                     fast_law._piece_source("_terms_0", list(constraint.symbolic_terms), chart))
    point = np.array([0.3, -0.4, 0.5])
    C, E_f, _ = module._terms_0(point, np.array([1.0, 0.0, 0.0]))
    assert C[0] == pytest.approx(0.3 * math.pi + math.sqrt(1.16) - math.exp(0.5), rel=1e-15)
    assert list(E_f[0]) == pytest.approx([math.pi, -0.4 / math.sqrt(1.16), -math.exp(0.5)], rel=1e-15)


# ------------------------------------------------------------------------------------------------
# D6: pydrake.symbolic variables and sympy symbols matched by their names only
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["_x", "__x", "_y", "x_", "X"])
def test_pydrake_variables_of_other_names_are_unknown(name):
    offset, y = drake_symbolic.Variable(name), drake_symbolic.Variable("y")
    with pytest.raises(UnknownVariableError, match=rf"constraint 'c' uses variables \['{name}'\]"):
        Constraint(CHART, [y - offset], name="c")


def test_pydrake_variables_and_plain_sympy_symbols_of_a_coordinate_name_are_that_coordinate():
    """A pydrake Variable 'x' and a sympy Symbol('x') without real=True are the chart's x: E_f = dC/dx
    (it was 0 for the sympy symbol: C did not depend on the chart's own x)."""
    point = np.array([0.5, 0.1, 0.0])
    x, y = drake_symbolic.Variable("x"), drake_symbolic.Variable("y")
    assert list(Constraint(CHART, [y - x * x]).force_projection(point)[0]) == pytest.approx([-1.0, 1.0, 0.0])
    x, y = sympy.symbols("x y")
    assert list(Constraint(CHART, [y - x**2]).force_projection(point)[0]) == pytest.approx([-1.0, 1.0, 0.0])


# ------------------------------------------------------------------------------------------------
# The checks: AutoDiffXd at the first call in the domain, and its gradients
# ------------------------------------------------------------------------------------------------

def far(name="far"):
    """A constraint defined nowhere near the sample points (|x| <= 1): checked at its first call."""
    return Constraint(CHART, [Y - sympy.sqrt(X - 5) * sympy.log(X - 5)], name=name)


def test_first_autodiff_call_in_the_domain_is_checked():
    constraint = far()
    assert constraint._value.checked_points == 0
    with pytest.raises(ValueError):
        constraint.value(np.array([1.0, 0.0, 0.0]))          # outside the domain: not checked, still to check
    assert constraint._value.checked_points == 0
    constraint.value(seeded([6.5, 0.0, 0.0]))
    assert constraint._value.checked_points == 1


def _wrong_sine_derivative(monkeypatch):
    wrong = symbolic._autodiff_function(math.sin, lambda u: 2 * math.cos(u))
    monkeypatch.setitem(symbolic._AUTODIFF_NAMESPACE, "sin", wrong)


def test_a_wrong_autodiff_derivative_is_caught_at_compile_time(monkeypatch):
    _wrong_sine_derivative(monkeypatch)
    with pytest.raises(CodeGenerationError, match=r"compiled C\[wrong\] \(AutoDiffXd\) d\(entry 0 = .*\)/dx gives"):
        Constraint(CHART, [Y - sympy.sin(X)], name="wrong")


def test_a_wrong_autodiff_derivative_is_caught_at_the_first_call(monkeypatch):
    _wrong_sine_derivative(monkeypatch)
    constraint = Constraint(CHART, [Y - sympy.sin(sympy.sqrt(X - 5))], name="wrong")   # no sample in domain
    with pytest.raises(CodeGenerationError, match=r"C\[wrong\] \(AutoDiffXd\) d\(entry 0 = .*\)/dx"):
        constraint.value(seeded([6.5, 0.0, 0.0]))


@pytest.mark.parametrize("expression, point", [
    (sympy.sqrt(X - 5) + sympy.Abs(Y), [6.0, 0.0, 0.0]),                            # |y| at its kink
    (sympy.sqrt(X - 5) + sympy.Piecewise((Y**2, Y > 0), (-Y, True)), [6.0, 0.0, 0.0]),  # a Piecewise boundary
    (sympy.sqrt(X - 5) + sympy.Max(Y, THETA), [6.0, 0.2, 0.2]),                      # Max on its switch
    (sympy.sqrt(X - 5) * 1e8 + Y, [6.0, 0.1, 0.0]),                                  # rounding of a large term
])
def test_first_call_checks_pass_at_kinks(expression, point):
    """The gradient check takes a one-sided derivative at a kink: no false alarm where the first call lands."""
    constraint = Constraint(CHART, [expression], name="kink")
    assert constraint._value.checked_points == 0
    constraint.value(np.array(point))
    constraint.force_projection(seeded(point))
    assert constraint._value.checked_points == 1 and constraint._force_projection.checked_points == 1


def test_numba_verification_uses_several_points():
    assert fast_law.NUMBA_POINTS >= 2
