"""The scenario files' expression grammar (core/expressions.py): what it builds, and that hostile
text is refused with bounded work (counted, not timed), naming the field and the offending token, without running anything."""

import bounded_work
import pytest
import sympy

from drake_hybrid.core.charts import PlanarChart
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.expressions import check_parameter_names, expression_to_sympy

CHART = PlanarChart()
X, Y, THETA = CHART.configuration_symbols
WHERE = "task.yaml: constraint.rows[0]"


def parse(text, parameters=None):
    return expression_to_sympy(text, CHART.configuration_symbols, parameters or {"height": 1.0, "radius": 0.02},
                               where=WHERE)


@pytest.mark.parametrize("text, expected", [
    ("y - (height - radius)", Y - sympy.Float(0.98)),
    ("x**2 + y**2 - 0.25", X**2 + Y**2 - sympy.Float(0.25)),
    ("-sin(theta) * 2 / 4", -sympy.sin(THETA) / 2),
    ("atan2(y, x) + sqrt(x) - exp(-theta) + log(2) + abs(y) + cos(pi/2)",
     sympy.atan2(Y, X) + sympy.sqrt(X) - sympy.exp(-THETA) + sympy.log(2) + sympy.Abs(Y)),
    ("+1.5e-3 * tan(theta)", sympy.Float(1.5e-3) * sympy.tan(THETA)),
    ("2 ** 10 * x", 1024 * X),
])
def test_grammar_builds_sympy(text, expected):
    assert sympy.simplify(parse(text) - expected) == 0


def test_numbers_are_expressions():
    assert parse(0.5) == sympy.Float(0.5) and parse(3) == 3


@pytest.mark.parametrize("text, token", [
    ("__import__('os').system('true')", "__import__"),
    ("x.__class__", "x.__class__"),
    ("().__class__.__bases__[0].__subclasses__()", "().__class__.__bases__[0].__subclasses__"),
    ("sin.__globals__", "sin.__globals__"),
    ("(lambda: 1)()", "lambda: 1"),
    ("[x for x in (1, 2)][0]", "[x for x in (1, 2)][0]"),
    ("x[0]", "x[0]"),
    ("[x for x in ()]", "[x for x in ()]"),
    ("'text'", "'text'"),
    ("open('/etc/passwd')", "open"),
    ("eval('1')", "eval"),
    ("z + 1", "z"),
    ("_x", "_x"),
    ("sin(x, y)", "sin(x, y)"),
    ("sin(x=1)", "sin(x=1)"),
    ("sin", "sin"),
    ("x if y else theta", "x if y else theta"),
    ("x < y", "x < y"),
    ("x and y", "x and y"),
    ("x // 2", "x // 2"),
    ("x % 2", "x % 2"),
    ("x @ y", "x @ y"),
    ("(x := 1)", "x := 1"),
    ("9 ** 9 ** 9", "9 ** 9"),
    ("10 ** 400", "10 ** 400"),
    ("x ** 1000", "x ** 1000"),
    ("(2 ** 64) ** 64", "(2 ** 64) ** 64"),
    ("x / 0", "x / 0"),
    ("1" * 60, "1" * 60),
    ("1j * x", "1j"),
    ("True + x", "True"),
    ("x +", "x +"),
    ("", ""),
])
def test_hostile_or_invalid_text_is_refused(text, token):
    count, error = bounded_work.calls(lambda: parse(text))
    assert isinstance(error, ConfigError), error
    message = str(error)
    assert message.startswith(WHERE) and "\n" not in message
    if token:
        assert token in message, message
    # Refused before anything is computed (9 ** 9 ** 9 is never evaluated): less work than a legitimate
    # expression that calls every function of the grammar (tests/bounded_work.py; no clock).
    assert count < bounded_work.calls(lambda: parse(EVERY_FUNCTION))[0], count


EVERY_FUNCTION = ("sin(x) + cos(y) + tan(theta) + asin(x) + acos(y) + atan(x) + atan2(y, x) + sinh(x) + cosh(y) "
                  "+ tanh(theta) + sqrt(x) + exp(-theta) + log(2) + abs(y) + pi")


@pytest.mark.parametrize("make, size", [(lambda n: "(" * n + "x" + ")" * n, 200), (lambda n: "-" * n + "x", 300),
                                        (lambda n: "+".join(["x"] * n), 2000), (lambda n: "x" * n, 5000),
                                        (lambda n: "sin(" * n + "x" + ")" * n, 100)],
                         ids=["brackets", "minus signs", "terms", "a long name", "calls"])
def test_deep_or_long_input_is_refused_with_bounded_work(make, size):
    """Twice as deep or as long costs at most about twice the calls (no blow-up; tests/bounded_work.py)."""
    counts = []
    for n in (size, 2 * size):
        count, error = bounded_work.calls(lambda: parse(make(n)))
        assert isinstance(error, ConfigError) and "task.yaml: constraint.rows" in str(error), error
        counts.append(count)
    assert bounded_work.at_most_linear(*counts), counts


def test_nothing_runs(tmp_path, monkeypatch):
    """A refused call of a builtin has no effect (the text is never evaluated)."""
    marker = tmp_path / "ran"
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError):
        parse(f"open('{marker}', 'w')")
    assert not marker.exists()


@pytest.mark.parametrize("parameters, match", [
    ({"x": 1.0}, "parameters.x: the name is taken"),
    ({"sin": 1.0}, "parameters.sin: the name is taken"),
    ({"_h": 1.0}, "identifier not starting with '_'"),
    ({"h": float("nan")}, "parameters.h must be a finite number"),
    ({"h": "1"}, "parameters.h must be a finite number"),
])
def test_parameter_names(parameters, match):
    with pytest.raises(ConfigError, match=match):
        check_parameter_names(parameters, CHART.configuration_symbols)
