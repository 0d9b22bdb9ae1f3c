"""Compile symbolic matrices into fast numeric functions for float and AutoDiffXd, checked against sympy.

A constraint C(r) written once by the user (sympy, or pydrake.symbolic) is
differentiated symbolically and turned into plain Python functions:

* a float version that uses ``math`` (runs every control tick), and
* an AutoDiffXd version that uses ``pydrake.math`` (runs when Drake's
  ``Linearize`` differentiates the controller).

Both are generated from one common-subexpression-eliminated (sympy ``cse``)
straight-line program; ``control/fast_law.py`` compiles the same program with numba.

Exact by construction, and checked. The printer parenthesizes every operand by its precedence
(a small integer power printed as a product is one operand: ``a/((b)*(b))``), prints constants as
numbers (an integer or rational of any size as its correctly rounded float) or names every path
defines, prints every symbol by a generated name (``_s0``, ``_s1``, ...: a coordinate may be called
anything), and refuses what no path can evaluate (``ExpressionError``: a row that is not an
expression, constants beyond the float range or complex, any node but numbers, symbols, + * ** and
``FUNCTIONS``). Then every compiled function is evaluated where it is compiled, at sample points (or
at its first call in the domain), and compared with sympy's own evaluation of the expression it came
from at 30 significant digits (``expr.evalf(30, subs=...)``, which shares none of this machinery); the
AutoDiffXd path's derivatives are compared with central differences of the float path, and with
sympy's derivative where those differ (``check_gradients``): a disagreement raises
``CodeGenerationError`` naming the term (``core.oracle``).
"""

import itertools
import math
import zlib

import numpy as np
import sympy
from sympy.printing.pycode import PythonCodePrinter

import pydrake.math as drake_math
import pydrake.symbolic as drake_symbolic
from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.core.errors import DimensionError, ExpressionError, UnknownVariableError
from drake_hybrid.core.oracle import check_against_sympy, check_gradients, describe, to_autodiff


class RealAbs(sympy.Function):
    """|u| of a real u. sympy's Abs differentiates as a complex function (re, im and arg of u appear
    where sympy cannot prove u real, e.g. |x**x|); every generated path computes in real numbers, where
    d|u| = sign(u) du. Printed as abs."""

    is_extended_real = True

    @classmethod
    def eval(cls, argument):
        if argument.is_number:
            return sympy.Abs(argument)
        return None

    def fdiff(self, argindex=1):
        return RealSign(self.args[0])

    def _eval_evalf(self, precision):
        return sympy.Abs(self.args[0]._eval_evalf(precision) or self.args[0])._eval_evalf(precision)


class RealSign(sympy.Function):
    """sign(u) of a real u, with the derivative zero wherever it exists (sign's DiracDelta is zero at
    every point but u = 0, where no derivative exists). Printed as _sign."""

    is_extended_real = True

    @classmethod
    def eval(cls, argument):
        if argument.is_number:
            return sympy.sign(argument)
        return None

    def fdiff(self, argindex=1):
        return sympy.S.Zero

    def _eval_evalf(self, precision):
        return sympy.sign(self.args[0]._eval_evalf(precision) or self.args[0])._eval_evalf(precision)


# The elementary functions generated code calls by name: math's for float (and numba), pydrake.math's
# for AutoDiffXd (asinh, acosh, atanh: math's value with the derivative, _AUTODIFF_INVERSE_HYPERBOLIC).
# |u| and sign(u) become RealAbs and RealSign (printed abs and _sign); DiracDelta (a derivative of sign,
# zero wherever it is defined) prints as 0; Piecewise as a conditional expression.
ELEMENTARY_FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp", "log", "sinh",
                        "cosh", "tanh", "asinh", "acosh", "atanh")
FUNCTIONS = frozenset([getattr(sympy, name) for name in ELEMENTARY_FUNCTIONS]
                      + [RealAbs, RealSign, sympy.DiracDelta, sympy.Piecewise])
# Terms rewritten into FUNCTIONS before anything is differentiated (exact identities for real arguments;
# none that loses accuracy in floating point: asinh, acosh and atanh are evaluated as themselves).
_REWRITES = {
    sympy.sec: lambda u: 1 / sympy.cos(u), sympy.csc: lambda u: 1 / sympy.sin(u), sympy.cot: lambda u: 1 / sympy.tan(u),
    sympy.acot: lambda u: sympy.atan(1 / u),
    sympy.Max: lambda *a: sympy.Max(*a).rewrite(sympy.Piecewise),
    sympy.Min: lambda *a: sympy.Min(*a).rewrite(sympy.Piecewise),
    sympy.Heaviside: lambda *a: sympy.Heaviside(*a).rewrite(sympy.Piecewise),
    sympy.Abs: RealAbs, sympy.sign: RealSign,
}
_ALLOWED_WORDS = ", ".join(ELEMENTARY_FUNCTIONS) + ", Abs, sign, Piecewise, sec, csc, cot, acot, Max, Min, Heaviside" \
    " (and numbers, coordinates, + - * / **, and the conditions of a Piecewise)"
# The nodes every path evaluates, besides FUNCTIONS: a row is built from these alone (check_functions).
_TERMS = (sympy.Symbol, sympy.Number, sympy.NumberSymbol, sympy.Add, sympy.Mul, sympy.Pow)
_CONDITIONS = (sympy.core.relational.Relational, sympy.And, sympy.Or, sympy.Not, sympy.logic.boolalg.BooleanAtom,
               sympy.functions.elementary.piecewise.ExprCondPair)
_LARGEST_EXACT_INTEGER = 2**31     # larger integer literals print as floats (numba's int64 must not overflow)


def _sign(value):
    """sign(value) for float and AutoDiffXd (a constant: its derivative is zero wherever it exists)."""
    return 1.0 if value > 0 else (-1.0 if value < 0 else 0.0)


SIGN_SOURCE = "def _sign(value):\n    return 1.0 if value > 0 else (-1.0 if value < 0 else 0.0)\n"


def _autodiff_function(function, derivative):
    """``function`` of a float, or of an AutoDiffXd u: function(u) to full float accuracy (math's), with the
    derivative ``derivative``(u) du. pydrake.math has no asinh, acosh, atanh; their log forms cancel
    (asinh at u << 0, atanh near 0)."""
    def evaluate(u):
        if isinstance(u, AutoDiffXd):
            value = u.value()
            return AutoDiffXd(function(value), derivative(value) * u.derivatives())
        return function(u)
    evaluate.__name__ = function.__name__
    return evaluate


def _acosh_derivative(u):
    square = (u - 1.0) * (u + 1.0)
    return 1.0 / math.sqrt(square) if square > 0 else math.inf


_AUTODIFF_INVERSE_HYPERBOLIC = {
    "asinh": _autodiff_function(math.asinh, lambda u: 1.0 / math.hypot(u, 1.0)),
    "acosh": _autodiff_function(math.acosh, _acosh_derivative),
    "atanh": _autodiff_function(math.atanh, lambda u: 1.0 / ((1.0 - u) * (1.0 + u))),
}

_FLOAT_NAMESPACE = {name: getattr(math, name) for name in ELEMENTARY_FUNCTIONS}
_FLOAT_NAMESPACE.update(pi=math.pi, E=math.e, abs=abs, pow=math.pow, _sign=_sign)

_AUTODIFF_NAMESPACE = {name: _AUTODIFF_INVERSE_HYPERBOLIC.get(name) or getattr(drake_math, name)
                       for name in ELEMENTARY_FUNCTIONS}
_AUTODIFF_NAMESPACE.update(pi=math.pi, E=math.e, abs=abs, pow=drake_math.pow, _sign=_sign)

_counter = itertools.count()


class _Printer(PythonCodePrinter):
    """Prints bare function names (``sin(x)``), resolved in the namespaces above, and every symbol by a
    generated name (``names``; a symbol not in it gets the next ``_s<k>``): a coordinate's own name may be
    no identifier ("x y", "x\u2081"), or one the generated code uses (pi, sqrt, _array)."""

    def __init__(self, names=None):
        super().__init__({"fully_qualified_modules": False, "inline": True})
        self.names = dict(names or {})
        self._next = len(set(self.names.values()))

    def _print_Symbol(self, expr):
        name = self.names.get(expr)
        if name is None:
            name = self.names[expr] = f"_s{self._next}"
            self._next += 1
        return name

    _print_Dummy = _print_Symbol

    def _print_Pow(self, expr, rational=False):
        base, exponent = expr.args
        b = self.parenthesize(base, 1000)
        if exponent.is_Integer and 1 <= abs(int(exponent)) <= 4:
            # Small integer powers as products: faster for float, exact for AutoDiffXd. The product is
            # parenthesized as a whole: a Pow may stand in a denominator, where "a/b*b" is (a/b)*b.
            product = "(" + "*".join([b] * abs(int(exponent))) + ")"
            return product if exponent > 0 else f"(1/{product})"
        if exponent == sympy.Rational(1, 2):
            return f"sqrt({self._print(base)})"
        if exponent == sympy.Rational(-1, 2):
            return f"(1/sqrt({self._print(base)}))"
        if exponent.is_number:
            # pow, not **: math.pow refuses a negative base with a fractional exponent (ValueError, as sqrt
            # and log do) where ** would return a complex number; pydrake.math.pow takes AutoDiffXd.
            return f"pow({self._print(base)}, {self._print(exponent)})"
        # A variable exponent: AutoDiffXd has no power of a variable exponent, so b**e = exp(e log b).
        return f"exp(({self._print(exponent)})*log({self._print(base)}))"

    def _print_Integer(self, expr):
        if abs(int(expr)) >= _LARGEST_EXACT_INTEGER:
            return repr(float(int(expr)))             # finite: prepare_expression refuses the rest
        return str(int(expr))

    def _print_Rational(self, expr):
        if abs(expr.p) < _LARGEST_EXACT_INTEGER and expr.q < _LARGEST_EXACT_INTEGER:
            return f"({expr.p}/{expr.q})"             # IEEE division: the correctly rounded value
        return repr(expr.p / expr.q)                  # Python's int division is correctly rounded too

    def _print_Half(self, expr):
        return "0.5"

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_Exp1(self, expr):
        return "E"

    def _print_Pi(self, expr):
        return "pi"

    def _print_RealSign(self, expr):
        return f"_sign({self._print(expr.args[0])})"

    def _print_RealAbs(self, expr):
        return f"abs({self._print(expr.args[0])})"

    def _print_DiracDelta(self, expr):
        return "0.0"


# ------------------------------------------------------------------------------------------------
# What can be compiled
# ------------------------------------------------------------------------------------------------

def prepare_expression(expression, what="expression"):
    """``expression`` (sympy) with the terms of ``_REWRITES`` rewritten into ``FUNCTIONS``.

    Raises ExpressionError naming ``what`` and the term: not an expression (a Boolean, a Relational, a
    Poly), a non-finite constant (nan, oo, zoo, a number beyond the float range), the imaginary unit, or a
    term no generated path evaluates (the message lists the allowed ones: ``check_functions``).
    """
    if not isinstance(expression, sympy.Basic):
        expression = sympy.sympify(expression)
    check_is_expression(expression, what)
    for constant, words in ((sympy.nan, "nan"), (sympy.zoo, "complex infinity (zoo)"), (sympy.oo, "infinity (oo)"),
                            (-sympy.oo, "infinity (-oo)"), (sympy.I, "the imaginary unit I")):
        if expression.has(constant):
            raise ExpressionError(f"{what}: {describe(expression)} contains {words}; expressions must be finite and "
                                  "real")
    for number in expression.atoms(sympy.Float, sympy.Rational):
        if not _is_finite_float(number):
            shown = sympy.Float(number, 6)
            raise ExpressionError(f"{what}: the constant {shown} in {describe(expression.xreplace({number: shown}))} "
                                  "is beyond the float range (|c| < 1.8e308); expressions must be finite")
    replacements = {term: _REWRITES[type(term)](*term.args) for term in expression.atoms(*_REWRITES)}
    if replacements:
        expression = expression.xreplace(replacements)
        return prepare_expression(expression, what)       # a rewritten argument may hold another rewrite
    check_functions(expression, what)
    check_constant_terms(expression, what)
    return expression


def _is_finite_float(number):
    """Whether the sympy Float or Rational ``number`` is a finite float (underflow to 0 is finite)."""
    try:
        value = float(number) if isinstance(number, sympy.Float) else number.p / number.q
    except OverflowError:
        return False
    return math.isfinite(value)


def check_is_expression(expression, what="expression"):
    """ExpressionError naming ``what`` if ``expression`` is not a sympy expression (a number-valued term):
    a comparison (x > 0), a Boolean, a Poly, a set."""
    if not isinstance(expression, sympy.Expr):
        raise ExpressionError(f"{what}: {describe(expression)} (a {type(expression).__name__}) is not an expression; "
                              "a row must be a number-valued sympy or pydrake.symbolic expression")


def check_constant_terms(expression, what="expression"):
    """ExpressionError naming ``what`` and the term if a constant sub-term (no symbol in it) is not a finite
    real number: acos(pi) or log(-1) is complex, and no real path evaluates it."""
    for term in sympy.preorder_traversal(expression):
        if term.free_symbols or not isinstance(term, (sympy.Function, sympy.Pow)):
            continue
        try:
            value = complex(term.evalf(30))
        except (TypeError, ValueError, ArithmeticError):
            value = complex("nan")
        if not (math.isfinite(value.real) and abs(value.imag) <= 1e-25 * max(1.0, abs(value.real))):
            raise ExpressionError(f"{what}: the constant term {describe(term)} is not a finite real number; "
                                  "expressions must be real")


def check_functions(expression, what="expression"):
    """ExpressionError naming ``what`` and the term if ``expression`` holds a node no generated path
    evaluates: a function outside ``FUNCTIONS`` (after differentiation too: an unevaluated Derivative of a
    user function), or any other sympy node (Sum, Product, Order, AccumBounds, Contains, Integral, ...).
    Allowed: symbols, numbers, ``+``, ``*``, ``**``, ``FUNCTIONS`` and, in a Piecewise, comparisons joined by And, Or, Not."""
    for term in sympy.preorder_traversal(expression):
        if isinstance(term, _TERMS) or type(term) in FUNCTIONS or isinstance(term, _CONDITIONS):
            continue
        name = getattr(type(term), "__name__", str(type(term)))
        kind = "function" if isinstance(term, sympy.Function) else "term"
        raise ExpressionError(f"{what}: the {kind} {name} in {describe(term)} cannot be compiled; "
                              f"allowed: {_ALLOWED_WORDS}")


def to_sympy_matrix(expressions, known_symbols, what="expression"):
    """Return ``expressions`` as a sympy Matrix over ``known_symbols``.

    Accepts a sympy Matrix, a (nested) list of sympy or pydrake.symbolic
    expressions, or numbers. pydrake.symbolic variables are matched to
    ``known_symbols`` by name. Raises UnknownVariableError naming every free
    variable that is not in ``known_symbols``, and ExpressionError for what cannot be
    compiled (``prepare_expression``).
    """
    # By name: a pydrake.symbolic Variable converts to a sympy Dummy of the Variable's name (its .name, not
    # str(), which prefixes '_'); a sympy Symbol of a coordinate's name but other assumptions is that
    # coordinate (else C would not depend on the chart's symbol: E_f = 0).
    by_name = {s.name: s for s in known_symbols}

    def convert(item):
        if isinstance(item, sympy.Basic):
            converted = item
        elif hasattr(item, "GetVariables") or type(item).__module__.startswith("pydrake.symbolic"):
            converted = drake_symbolic.to_sympy(item)
        else:
            try:
                converted = sympy.sympify(item, strict=True)
            except (sympy.SympifyError, TypeError, ValueError) as error:
                raise ExpressionError(f"{what}: {item!r} ({type(item).__name__}) is not an expression") from error
        check_is_expression(converted, what)
        return converted.xreplace({s: by_name[s.name] for s in converted.free_symbols
                                   if s.name in by_name and s != by_name[s.name]})

    if isinstance(expressions, sympy.MatrixBase):
        matrix = sympy.Matrix(expressions).applyfunc(convert)
    else:
        rows = list(expressions) if not isinstance(expressions, sympy.Basic) else [expressions]
        if rows and isinstance(rows[0], (list, tuple, np.ndarray)):
            matrix = sympy.Matrix([[convert(e) for e in row] for row in rows])
        else:
            matrix = sympy.Matrix([convert(e) for e in rows])
    unknown = sorted({s.name for s in matrix.free_symbols} - set(by_name))
    if unknown:
        raise UnknownVariableError(
            f"{what} uses variables {unknown} that are not coordinates of the chart; "
            f"allowed variables are {list(by_name)}"
        )
    return matrix.applyfunc(lambda entry: prepare_expression(entry, what))


# ------------------------------------------------------------------------------------------------
# Compiled functions
# ------------------------------------------------------------------------------------------------

class CompiledFunction:
    """A numeric function of one or more argument vectors, compiled from sympy and checked against it.

    ``CompiledFunction(name, [symbols_a, symbols_b], matrix)(a, b)`` returns
    ``matrix`` evaluated at ``symbols_a = a`` and ``symbols_b = b`` as a numpy
    array of ``matrix.shape`` (or a vector when ``matrix`` is a column and
    ``vector=True``). If any argument has dtype object (AutoDiffXd), the
    AutoDiffXd version runs and the result has dtype object.

    Both versions are checked against sympy when compiled (``check_against_sympy``: the values; and
    ``check_gradients``: the AutoDiffXd path's derivatives); where no sample point lies in the domain of
    every entry, the first call that does (float or AutoDiffXd, at its values; up to ``FIRST_CALLS_CHECKED``
    calls) is checked instead. ``checked_points`` says how many points were checked.

    Raises ExpressionError (what cannot be compiled) and CodeGenerationError (a disagreement).
    """

    FIRST_CALLS_CHECKED = 20      # calls tried for a point in the domain when no sample point was

    def __init__(self, name, argument_symbols, matrix, vector=False):
        self.name = name
        self.argument_symbols = [tuple(group) for group in argument_symbols]
        self.argument_sizes = [len(group) for group in self.argument_symbols]
        matrix = sympy.Matrix(matrix)
        self.shape = (matrix.rows,) if vector else matrix.shape
        self._entries = list(matrix)           # as given: the oracle evaluates them before any rewriting
        source = self._generate_source(matrix)
        self.source = source
        self._float = self._build(source, _FLOAT_NAMESPACE, float)
        self._autodiff = self._build(source, _AUTODIFF_NAMESPACE, object)
        self.checked_points = self._check()
        self._calls_to_check = 0 if self.checked_points else self.FIRST_CALLS_CHECKED

    def _generate_source(self, matrix):
        assignments, results, printer = straight_line_program(list(matrix), self.name)
        function_name = f"_compiled_{next(_counter)}"
        lines = [f"def {function_name}({', '.join(f'_arg{i}' for i in range(len(self.argument_symbols)))}):"]
        for i, group in enumerate(self.argument_symbols):
            if group:
                names = ", ".join(printer.doprint(s) for s in group)
                lines.append(f"    {names}, = _arg{i}")
        for target, code in assignments:
            lines.append(f"    {target} = {code}")
        lines.append(f"    return _array(({', '.join(results)},), _dtype).reshape(_shape)")
        return "\n".join(lines), function_name

    def _build(self, source_and_name, namespace, dtype):
        source, function_name = source_and_name
        scope = dict(namespace)
        scope.update(_array=np.array, _dtype=dtype, _shape=self.shape)
        exec(compile(source, f"<drake_hybrid.core.symbolic:{self.name}>", "exec"), scope)
        return scope[function_name]

    def _check(self, at=None):
        if not self._entries:
            return 0
        float_at = None if at is None else [np.asarray(a, dtype=float) for a in at]
        paths = {"float": self._float,
                 "AutoDiffXd": lambda *arguments: self._autodiff(*[to_autodiff(a) for a in arguments])}

        def gradients(point, substitutions):
            check_gradients(self.name, self._entries, self.argument_symbols, self._float, self._autodiff, point,
                            substitutions)

        return check_against_sympy(self.name, self._entries, self.argument_symbols, paths,
                                   seed=zlib.crc32(self.source[0].encode()), at=float_at, then=gradients)

    def __call__(self, *arguments):
        if len(arguments) != len(self.argument_sizes):
            raise TypeError(f"{self.name} takes {len(self.argument_sizes)} arguments, got {len(arguments)}")
        autodiff = False
        for argument, size in zip(arguments, self.argument_sizes):
            if len(argument) != size:
                raise DimensionError(f"{self.name}: expected an argument of size {size}, got {len(argument)}")
            if getattr(argument, "dtype", None) == object:
                autodiff = True
        if self._calls_to_check:
            self._calls_to_check -= 1
            at = [_values(argument) for argument in arguments] if autodiff else list(arguments)
            self.checked_points = self._check(at=at)
            if self.checked_points:
                self._calls_to_check = 0
        if autodiff:
            return self._autodiff(*arguments)
        return self._float(*arguments)


def _values(argument):
    """The float values of an argument that may hold AutoDiffXd scalars."""
    return np.array([entry.value() if isinstance(entry, AutoDiffXd) else float(entry) for entry in argument])


def straight_line_program(entries, what="expression"):
    """(assignments, results, printer) of one CSE program for the sympy ``entries``, printed as Python with
    bare function names (``sin(x)``), as the compiled functions above: ``assignments`` is a list of
    (name, code), ``results`` the code of each entry. Every symbol is printed by a generated name
    (``_s0``, ``_s1``, ...; ``printer.doprint(symbol)`` gives a symbol's, so callers bind their arguments by
    it) and every CSE temporary as ``_t0``, ``_t1``, ...: no name of the user's reaches the code.
    control/fast_law.py compiles it with numba (with ``SIGN_SOURCE`` and the elementary functions from
    ``math`` in its module)."""
    entries = [prepare_expression(entry, what) for entry in entries]
    symbols = list(sympy.ordered(set().union(*[entry.free_symbols for entry in entries])))
    safe = {symbol: sympy.Dummy(f"s{i}", **symbol.assumptions0) for i, symbol in enumerate(symbols)}
    names = {symbol: f"_s{i}" for i, symbol in enumerate(symbols)}
    names.update({safe[symbol]: name for symbol, name in names.items()})
    entries = [entry.xreplace(safe) for entry in entries]
    replacements, reduced = sympy.cse(entries, symbols=sympy.numbered_symbols("t", cls=sympy.Dummy),
                                      optimizations="basic")
    names.update({symbol: f"_t{i}" for i, (symbol, _) in enumerate(replacements)})
    printer = _Printer(names)
    assignments = [(printer.doprint(symbol), printer.doprint(expression)) for symbol, expression in replacements]
    return assignments, [printer.doprint(e) for e in reduced], printer


def time_derivative(matrix, configuration_symbols, configuration_rate):
    """d/dt of a sympy matrix of the configuration x along x-dot = ``configuration_rate``:
    sum_i (d matrix / d x_i) x-dot_i."""
    rate = sympy.zeros(*matrix.shape)
    for symbol, symbol_rate in zip(configuration_symbols, configuration_rate):
        if symbol_rate != 0:
            rate += matrix.diff(symbol) * symbol_rate
    return rate


def compiled_time_derivative(name, matrix, chart):
    """The CompiledFunction (x, nu) -> d/dt ``matrix``(x) along x-dot = L(x) nu of ``chart``."""
    rate = time_derivative(matrix, chart.configuration_symbols, chart.configuration_rate)
    return CompiledFunction(name, [chart.configuration_symbols, chart.velocity_symbols], rate)
