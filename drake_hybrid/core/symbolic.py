"""Compile symbolic matrices into fast numeric functions for float and AutoDiffXd.

A constraint C(r) written once by the user (sympy, or pydrake.symbolic) is
differentiated symbolically and turned into plain Python functions:

* a float version that uses ``math`` (runs every control tick), and
* an AutoDiffXd version that uses ``pydrake.math`` (runs when Drake's
  ``Linearize`` differentiates the controller).

Both are generated from one common-subexpression-eliminated (sympy ``cse``)
straight-line program, so they always agree.
"""

import itertools
import math

import numpy as np
import sympy
from sympy.printing.pycode import PythonCodePrinter

import pydrake.math as drake_math
import pydrake.symbolic as drake_symbolic

from drake_hybrid.core.errors import DimensionError, UnknownVariableError

_FLOAT_NAMESPACE = {
    name: getattr(math, name)
    for name in ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp", "log", "sinh", "cosh", "tanh")
}
_FLOAT_NAMESPACE.update(pi=math.pi, E=math.e, abs=abs)

_AUTODIFF_NAMESPACE = {
    name: getattr(drake_math, name)
    for name in ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp", "log", "sinh", "cosh", "tanh")
}
_AUTODIFF_NAMESPACE.update(pi=math.pi, E=math.e, abs=abs)

_counter = itertools.count()


class _Printer(PythonCodePrinter):
    """Prints bare function names (``sin(x)``), resolved in the namespaces above."""

    def __init__(self):
        super().__init__({"fully_qualified_modules": False, "inline": True})

    def _print_Pow(self, expr, rational=False):
        # Small integer powers as products: faster for float, exact for AutoDiffXd.
        base, exponent = expr.as_base_exp()
        if exponent.is_Integer and 2 <= int(exponent) <= 4:
            # The product is parenthesized as a whole: a Pow may stand in a denominator, where
            # "a/b*b" would be read as (a/b)*b.
            b = self.parenthesize(base, 1000)
            return "(" + "*".join([b] * int(exponent)) + ")"
        if exponent == sympy.Rational(1, 2):
            return f"sqrt({self._print(base)})"
        return super()._print_Pow(expr, rational=rational)


def to_sympy_matrix(expressions, known_symbols, what="expression"):
    """Return ``expressions`` as a sympy Matrix over ``known_symbols``.

    Accepts a sympy Matrix, a (nested) list of sympy or pydrake.symbolic
    expressions, or numbers. pydrake.symbolic variables are matched to
    ``known_symbols`` by name. Raises UnknownVariableError naming every free
    variable that is not in ``known_symbols``.
    """
    by_name = {str(s): s for s in known_symbols}

    def convert(item):
        if isinstance(item, sympy.Basic):
            return item
        if hasattr(item, "GetVariables") or type(item).__module__.startswith("pydrake.symbolic"):
            converted = drake_symbolic.to_sympy(item)
            substitutions = {s: by_name[str(s).lstrip("_")] for s in converted.free_symbols if str(s).lstrip("_") in by_name}
            return converted.xreplace(substitutions)
        return sympy.sympify(item)

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
    return matrix


class CompiledFunction:
    """A numeric function of one or more argument vectors, compiled from sympy.

    ``CompiledFunction(name, [symbols_a, symbols_b], matrix)(a, b)`` returns
    ``matrix`` evaluated at ``symbols_a = a`` and ``symbols_b = b`` as a numpy
    array of ``matrix.shape`` (or a vector when ``matrix`` is a column and
    ``vector=True``). If any argument has dtype object (AutoDiffXd), the
    AutoDiffXd version runs and the result has dtype object.
    """

    def __init__(self, name, argument_symbols, matrix, vector=False):
        self.name = name
        self.argument_symbols = [tuple(group) for group in argument_symbols]
        self.argument_sizes = [len(group) for group in self.argument_symbols]
        matrix = sympy.Matrix(matrix)
        self.shape = (matrix.rows,) if vector else matrix.shape
        source = self._generate_source(matrix)
        self.source = source
        self._float = self._build(source, _FLOAT_NAMESPACE, float)
        self._autodiff = self._build(source, _AUTODIFF_NAMESPACE, object)

    def _generate_source(self, matrix):
        printer = _Printer()
        entries = list(matrix)
        replacements, reduced = sympy.cse(entries, symbols=sympy.numbered_symbols("_t"), optimizations="basic")
        function_name = f"_compiled_{next(_counter)}"
        lines = [f"def {function_name}({', '.join(f'_arg{i}' for i in range(len(self.argument_symbols)))}):"]
        for i, group in enumerate(self.argument_symbols):
            if group:
                names = ", ".join(printer.doprint(s) for s in group)
                lines.append(f"    {names}, = _arg{i}")
        for symbol, expression in replacements:
            lines.append(f"    {printer.doprint(symbol)} = {printer.doprint(expression)}")
        values = ", ".join(printer.doprint(e) for e in reduced)
        lines.append(f"    return _array(({values},), _dtype).reshape(_shape)")
        return "\n".join(lines), function_name

    def _build(self, source_and_name, namespace, dtype):
        source, function_name = source_and_name
        scope = dict(namespace)
        scope.update(_array=np.array, _dtype=dtype, _shape=self.shape)
        exec(compile(source, f"<drake_hybrid.core.symbolic:{self.name}>", "exec"), scope)
        return scope[function_name]

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
        return self._float(*arguments)


def straight_line_program(entries):
    """(assignments, results) of one CSE program for the sympy ``entries``, printed as Python with bare
    function names (``sin(x)``), as the compiled functions above: ``assignments`` is a list of
    (name, code), ``results`` the code of each entry. control/fast_law.py compiles it with numba."""
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
