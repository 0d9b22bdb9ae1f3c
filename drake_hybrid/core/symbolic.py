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
numbers or names every path defines, and refuses what no path can evaluate (``ExpressionError``:
non-finite or complex constants, functions outside ``FUNCTIONS``). Then every compiled function is
evaluated where it is compiled, at sample points, and compared with sympy's own evaluation of the
expression it came from at 30 significant digits (``expr.evalf(30, subs=...)``, which shares none of
this machinery), the way a linearization checks Drake's AutoDiffXd Jacobian against central
differences: a disagreement raises ``CodeGenerationError`` naming the term (``core.oracle``).
"""

import itertools
import math
import zlib

import numpy as np
import sympy
from sympy.printing.pycode import PythonCodePrinter

import pydrake.math as drake_math
import pydrake.symbolic as drake_symbolic

from drake_hybrid.core.errors import DimensionError, ExpressionError, UnknownVariableError
from drake_hybrid.core.oracle import check_against_sympy, describe, to_autodiff

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
# for AutoDiffXd. |u| and sign(u) become RealAbs and RealSign (printed abs and _sign); DiracDelta (a
# derivative of sign, zero wherever it is defined) prints as 0; Piecewise as a conditional expression.
ELEMENTARY_FUNCTIONS = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp", "log", "sinh",
                        "cosh", "tanh")
FUNCTIONS = frozenset([getattr(sympy, name) for name in ELEMENTARY_FUNCTIONS]
                      + [RealAbs, RealSign, sympy.DiracDelta, sympy.Piecewise])
# Functions rewritten into FUNCTIONS before anything is differentiated (exact identities for real arguments).
_REWRITES = {
    sympy.sec: lambda u: 1 / sympy.cos(u), sympy.csc: lambda u: 1 / sympy.sin(u), sympy.cot: lambda u: 1 / sympy.tan(u),
    sympy.asinh: lambda u: sympy.log(u + sympy.sqrt(u**2 + 1)),
    sympy.acosh: lambda u: sympy.log(u + sympy.sqrt(u - 1) * sympy.sqrt(u + 1)),
    sympy.atanh: lambda u: (sympy.log(1 + u) - sympy.log(1 - u)) / 2,
    sympy.acot: lambda u: sympy.atan(1 / u),
    sympy.Max: lambda *a: sympy.Max(*a).rewrite(sympy.Piecewise),
    sympy.Min: lambda *a: sympy.Min(*a).rewrite(sympy.Piecewise),
    sympy.Heaviside: lambda *a: sympy.Heaviside(*a).rewrite(sympy.Piecewise),
    sympy.Abs: RealAbs, sympy.sign: RealSign,
}
_ALLOWED_WORDS = ", ".join(ELEMENTARY_FUNCTIONS) + ", Abs, sign, Piecewise, sec, csc, cot, acot, asinh, acosh, " \
    "atanh, Max, Min, Heaviside"
_LARGEST_EXACT_INTEGER = 2**31     # larger integer literals print as floats (numba's int64 must not overflow)


def _sign(value):
    """sign(value) for float and AutoDiffXd (a constant: its derivative is zero wherever it exists)."""
    return 1.0 if value > 0 else (-1.0 if value < 0 else 0.0)


SIGN_SOURCE = "def _sign(value):\n    return 1.0 if value > 0 else (-1.0 if value < 0 else 0.0)\n"

_FLOAT_NAMESPACE = {name: getattr(math, name) for name in ELEMENTARY_FUNCTIONS}
_FLOAT_NAMESPACE.update(pi=math.pi, E=math.e, abs=abs, pow=math.pow, _sign=_sign)

_AUTODIFF_NAMESPACE = {name: getattr(drake_math, name) for name in ELEMENTARY_FUNCTIONS}
_AUTODIFF_NAMESPACE.update(pi=math.pi, E=math.e, abs=abs, pow=drake_math.pow, _sign=_sign)

_counter = itertools.count()


class _Printer(PythonCodePrinter):
    """Prints bare function names (``sin(x)``), resolved in the namespaces above."""

    def __init__(self):
        super().__init__({"fully_qualified_modules": False, "inline": True})

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
            return repr(float(expr))
        return str(int(expr))

    def _print_Rational(self, expr):
        return f"({self._print(sympy.Integer(expr.p))}/{self._print(sympy.Integer(expr.q))})"

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
    """``expression`` (sympy) with the functions of ``_REWRITES`` rewritten into ``FUNCTIONS``.

    Raises ExpressionError naming ``what`` and the term: a non-finite constant (nan, oo, zoo), the
    imaginary unit, or a function no generated path evaluates (the message lists the allowed ones).
    """
    if not isinstance(expression, sympy.Basic):
        expression = sympy.sympify(expression)
    for constant, words in ((sympy.nan, "nan"), (sympy.zoo, "complex infinity (zoo)"), (sympy.oo, "infinity (oo)"),
                            (-sympy.oo, "infinity (-oo)"), (sympy.I, "the imaginary unit I")):
        if expression.has(constant):
            raise ExpressionError(f"{what}: {describe(expression)} contains {words}; expressions must be finite and "
                                  "real")
    for number in expression.atoms(sympy.Float):
        if not math.isfinite(float(number)):
            raise ExpressionError(f"{what}: {describe(expression)} contains the constant {number}, which is not a "
                                  "finite float")
    replacements = {}
    for function in expression.atoms(sympy.Function):
        rewrite = _REWRITES.get(type(function))
        if rewrite is not None:
            replacements[function] = rewrite(*function.args)
    if replacements:
        expression = expression.xreplace(replacements)
        return prepare_expression(expression, what)       # a rewritten argument may hold another rewrite
    check_functions(expression, what)
    return expression


def check_functions(expression, what="expression"):
    """ExpressionError naming ``what`` and the function if ``expression`` calls one outside ``FUNCTIONS``
    (after differentiation too: e.g. an unevaluated Derivative of a user function)."""
    for function in expression.atoms(sympy.Function, sympy.Derivative, sympy.Subs, sympy.Integral):
        if type(function) not in FUNCTIONS:
            name = getattr(type(function), "__name__", str(type(function)))
            raise ExpressionError(f"{what}: the function {name} in {describe(function)} cannot be compiled; "
                                  f"allowed: {_ALLOWED_WORDS}")


def to_sympy_matrix(expressions, known_symbols, what="expression"):
    """Return ``expressions`` as a sympy Matrix over ``known_symbols``.

    Accepts a sympy Matrix, a (nested) list of sympy or pydrake.symbolic
    expressions, or numbers. pydrake.symbolic variables are matched to
    ``known_symbols`` by name. Raises UnknownVariableError naming every free
    variable that is not in ``known_symbols``, and ExpressionError for what cannot be
    compiled (``prepare_expression``).
    """
    by_name = {str(s): s for s in known_symbols}

    def convert(item):
        if isinstance(item, sympy.Basic):
            return item
        if hasattr(item, "GetVariables") or type(item).__module__.startswith("pydrake.symbolic"):
            converted = drake_symbolic.to_sympy(item)
            substitutions = {s: by_name[str(s).lstrip("_")] for s in converted.free_symbols if str(s).lstrip("_") in by_name}
            return converted.xreplace(substitutions)
        try:
            return sympy.sympify(item, strict=True)
        except (sympy.SympifyError, TypeError, ValueError) as error:
            raise ExpressionError(f"{what}: {item!r} ({type(item).__name__}) is not an expression") from error

    if isinstance(expressions, sympy.MatrixBase):
        matrix = sympy.Matrix(expressions)
    else:
        rows = list(expressions) if not isinstance(expressions, sympy.Basic) else [expressions]
        if rows and isinstance(rows[0], (list, tuple, np.ndarray)):
            matrix = sympy.Matrix([[convert(e) for e in row] for row in rows])
        else:
            matrix = sympy.Matrix([convert(e) for e in rows])
    unknown = sorted({str(s) for s in matrix.free_symbols} - set(by_name))
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

    Both versions are checked against sympy when compiled (``check_against_sympy``); where no sample
    point lies in the domain of every entry, the first float call is checked instead.
    ``checked_points`` says how many points were checked.

    Raises ExpressionError (what cannot be compiled) and CodeGenerationError (a disagreement).
    """

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
        self._check_first_call = self.checked_points == 0

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
        return check_against_sympy(self.name, self._entries, self.argument_symbols, paths,
                                   seed=zlib.crc32(self.source[0].encode()), at=float_at)

    def __call__(self, *arguments):
        if len(arguments) != len(self.argument_sizes):
            raise TypeError(f"{self.name} takes {len(self.argument_sizes)} arguments, got {len(arguments)}")
        autodiff = False
        for argument, size in zip(arguments, self.argument_sizes):
            if len(argument) != size:
                raise DimensionError(f"{self.name}: expected an argument of size {size}, got {len(argument)}")
            if getattr(argument, "dtype", None) == object:
                autodiff = True
        if autodiff:
            return self._autodiff(*arguments)
        if self._check_first_call:
            self._check_first_call = False
            self.checked_points = self._check(at=list(arguments))
        return self._float(*arguments)


def straight_line_program(entries, what="expression"):
    """(assignments, results, printer) of one CSE program for the sympy ``entries``, printed as Python with
    bare function names (``sin(x)``), as the compiled functions above: ``assignments`` is a list of
    (name, code), ``results`` the code of each entry. control/fast_law.py compiles it with numba (with
    ``SIGN_SOURCE`` and the elementary functions from ``math`` in its module)."""
    entries = [prepare_expression(entry, what) for entry in entries]
    printer = _Printer()
    replacements, reduced = sympy.cse(list(entries), symbols=sympy.numbered_symbols("_t"), optimizations="basic")
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
