"""Expressions from text (scenario files) turned into sympy, by a whitelisted grammar.

A scenario file written by someone else must not be able to run code, so the text of an expression
is never given to ``eval``, ``exec`` or ``sympy.sympify``. It is parsed by Python's ``ast`` module
(which only builds a tree, it runs nothing) and the tree is walked here; every node that is not in
the grammar below is refused with a ConfigError naming the file, the field and the offending token::

    expression := number | name | expression OP expression | ('-' | '+') expression
                | '(' expression ')' | function '(' expression {',' expression} ')'
    OP         := '+' | '-' | '*' | '/' | '**'
    name       := a coordinate of the chart | a named parameter of the file | 'pi'
    function   := one of FUNCTIONS (sin, cos, tan, ..., atan2, sqrt, exp, log, abs)

Anything else (attribute access, subscripts, calls of other names, keyword arguments, lambdas,
comprehensions, strings, comparisons, names starting with '_') is refused. Limits that keep a
hostile text from costing time or memory before anything is built: at most ``MAX_LENGTH``
characters, ``MAX_DEPTH`` levels of nesting, ``MAX_NODES`` tree nodes, numeric literals of at most
``MAX_DIGITS`` characters, numeric exponents of magnitude at most ``MAX_EXPONENT``, and a number
raised to a number, and every constant of the result, must stay below 1e300.

Names are read as Python reads identifiers: NFKC-normalized ('ℌ' is 'H', the micro sign 'µ' is the
Greek 'μ'); parameter names that are one name once normalized are refused (``check_parameter_names``).

    expression_to_sympy("y - (height - radius)", symbols=chart.configuration_symbols,
                        parameters={"height": 1.0, "radius": 0.02}, where="task.yaml: constraint.rows[0]")
"""

import ast
import keyword
import math
import unicodedata

import sympy

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.schema import nesting_depth

MAX_LENGTH = 2000          # characters of one expression
MAX_DEPTH = 40             # nesting levels (brackets, operators, calls)
MAX_NODES = 500            # nodes of the parsed tree
MAX_DIGITS = 40            # characters of one numeric literal
MAX_EXPONENT = 100         # |p| of a numeric exponent in a ** p
MAX_MAGNITUDE_LOG10 = 300  # a number raised to a number stays below 10**300

# name: (sympy function, number of arguments)
FUNCTIONS = {
    "sin": (sympy.sin, 1), "cos": (sympy.cos, 1), "tan": (sympy.tan, 1),
    "asin": (sympy.asin, 1), "acos": (sympy.acos, 1), "atan": (sympy.atan, 1), "atan2": (sympy.atan2, 2),
    "sinh": (sympy.sinh, 1), "cosh": (sympy.cosh, 1), "tanh": (sympy.tanh, 1),
    "sqrt": (sympy.sqrt, 1), "exp": (sympy.exp, 1), "log": (sympy.log, 1), "abs": (sympy.Abs, 1),
}
CONSTANTS = {"pi": sympy.pi}
_OPERATORS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}


def _refuse(where, reason, token):
    raise ConfigError(f"{where}: {reason} '{token}'")


def normalized(name):
    """``name`` as an expression reads it: Python's parser NFKC-normalizes identifiers, so the text
    'ℌ' or 'µ' (MICRO SIGN) is the name 'H' or 'μ' (GREEK SMALL LETTER MU)."""
    return unicodedata.normalize("NFKC", name)


def check_parameter_names(parameters, symbols, where="parameters"):
    """ConfigError if a parameter name is not a plain identifier, is a Python keyword, starts with '_',
    shadows a chart coordinate, a function or a constant, or is another parameter's name once
    normalized as expressions read names (``normalized``: 'ℌ' is 'H'); or if its value is not a finite
    number."""
    taken = {normalized(str(s)) for s in symbols}
    seen = {}
    for name, number in parameters.items():
        if not isinstance(name, str) or not name.isidentifier() or normalized(name).startswith("_"):
            raise ConfigError(f"{where}: a parameter name must be an identifier not starting with '_', got '{name}'")
        if keyword.iskeyword(normalized(name)):
            raise ConfigError(f"{where}: a parameter name must not be a Python keyword, got '{name}'")
        read = normalized(name)
        if read in seen:
            raise ConfigError(f"{where}: the parameters '{seen[read]}' and '{name}' are one name ('{read}') in an "
                              "expression (Unicode NFKC normalization); rename one")
        seen[read] = name
        if read in taken or read in FUNCTIONS or read in CONSTANTS:
            raise ConfigError(f"{where}.{name}: the name is taken by a chart coordinate, a function or a constant; "
                              "rename the parameter")
        if isinstance(number, bool) or not isinstance(number, (int, float)) or not math.isfinite(number):
            raise ConfigError(f"{where}.{name} must be a finite number, got {number!r}")


def expression_to_sympy(text, symbols=(), parameters=None, where="expression", row=False):
    """The sympy expression of ``text`` (see the module docstring for the grammar).

    Args:
        text: the expression (a str; a number is accepted as its own expression).
        symbols: the chart's coordinates (sympy Symbols, referred to by name).
        parameters: {name: number}, substituted as sympy Floats.
        where: "file: field" for the error messages.
        row: accept a top-level tuple "a, b, c" and return a list (``expression_row_to_sympy``).

    Raises ConfigError (one line: ``where``, the reason and the offending token).
    """
    if isinstance(text, bool):
        _refuse(where, "expected an expression, got", text)
    if isinstance(text, (int, float)):
        if not math.isfinite(text):
            _refuse(where, "numbers must be finite, got", text)
        number = _finite(sympy.Integer(text) if isinstance(text, int) else sympy.Float(text), where, str(text)[:60])
        return [number] if row else number
    if not isinstance(text, str):
        _refuse(where, "expected an expression (text), got", type(text).__name__)
    if len(text) > MAX_LENGTH:
        _refuse(where, f"the expression is longer than {MAX_LENGTH} characters:", text[:40] + "...")
    if not text.strip():
        _refuse(where, "the expression is empty:", text)
    if nesting_depth(text, "([{", ")]}") > MAX_DEPTH:
        _refuse(where, f"the expression nests brackets deeper than {MAX_DEPTH} levels:", text[:40] + "...")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as error:
        token = (error.text or text).strip()[max(0, (error.offset or 1) - 1):][:20] or text[:20]
        _refuse(where, f"not a valid expression ({error.msg}) at", token)
    except (ValueError, RecursionError, MemoryError):
        _refuse(where, "not a valid expression:", text[:40])
    nodes = sum(1 for _ in ast.walk(tree))
    if nodes > MAX_NODES:
        _refuse(where, f"the expression has more than {MAX_NODES} terms:", text[:40] + "...")
    # names as the parser reads them (NFKC): the lookup of an ast.Name's id
    by_name = {normalized(str(s)): s for s in symbols}
    values = {normalized(name): sympy.Float(float(number)) for name, number in (parameters or {}).items()}
    converter = _Converter(text, where, by_name, values)
    if row and isinstance(tree.body, ast.Tuple):
        return [_finite(converter.convert(item, 2), where, text) for item in tree.body.elts]
    result = _finite(converter.convert(tree.body, 1), where, text)
    return [result] if row else result


def _finite(expression, where, text):
    """``expression`` if each of its numbers (the products and quotients of the numbers written, as sympy
    collects them) is below 10**MAX_MAGNITUDE_LOG10; else ConfigError."""
    limit = sympy.Integer(10)**MAX_MAGNITUDE_LOG10
    for number in expression.atoms(sympy.Number):
        if abs(number) > limit:
            _refuse(where, f"a constant beyond 1e{MAX_MAGNITUDE_LOG10} ({sympy.Float(number, 3)}) in", text[:60])
    return expression


def expression_row_to_sympy(text, size, symbols=(), parameters=None, where="expression"):
    """A row of ``size`` expressions written as one text, separated by commas ("cos(theta), 0, 1"),
    as a list of sympy expressions (the grammar of ``expression_to_sympy`` for each entry)."""
    entries = expression_to_sympy(text, symbols, parameters, where, row=True)
    if len(entries) != size:
        _refuse(where, f"expected {size} comma-separated entries, got {len(entries)} in", text)
    return entries


class _Converter:
    """Walks an ``ast`` tree of the grammar, building sympy; refuses every other node."""

    def __init__(self, text, where, symbols, parameters):
        self.text, self.where, self.symbols, self.parameters = text, where, symbols, parameters

    def token(self, node):
        return ast.get_source_segment(self.text.strip(), node) or type(node).__name__

    def refuse(self, reason, node):
        _refuse(self.where, reason, self.token(node))

    def convert(self, node, depth):
        if depth > MAX_DEPTH:
            self.refuse(f"the expression nests deeper than {MAX_DEPTH} levels at", node)
        if isinstance(node, ast.Constant):
            return self.number(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            operand = self.convert(node.operand, depth + 1)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
            left = self.convert(node.left, depth + 1)
            right = self.convert(node.right, depth + 1)
            return self.binary(node, left, right)
        if isinstance(node, ast.Call):
            return self.call(node, depth)
        if isinstance(node, ast.BinOp):
            self.refuse("operator not allowed (only + - * / **):", node)
        self.refuse(f"not allowed in an expression ({_describe(node)}):", node)

    def number(self, node):
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.refuse(f"not allowed in an expression ({_describe(node)}):", node)
        if len(self.token(node)) > MAX_DIGITS:
            self.refuse(f"a number of more than {MAX_DIGITS} characters:", node)
        if isinstance(value, float):
            if not math.isfinite(value):
                self.refuse("numbers must be finite:", node)
            return sympy.Float(value)
        return sympy.Integer(value)

    def name(self, node):
        name = node.id
        if name.startswith("_"):
            self.refuse("names starting with '_' are not allowed:", node)
        if name in self.symbols:
            return self.symbols[name]
        if name in self.parameters:
            return self.parameters[name]
        if name in CONSTANTS:
            return CONSTANTS[name]
        if name in FUNCTIONS:
            self.refuse("a function must be called with its arguments:", node)
        known = sorted(self.symbols) + sorted(self.parameters) + sorted(CONSTANTS)
        self.refuse(f"unknown name (allowed: the chart's coordinates and parameters {known}):", node)

    def binary(self, node, left, right):
        operator = type(node.op)
        if operator is ast.Add:
            return left + right
        if operator is ast.Sub:
            return left - right
        if operator is ast.Mult:
            return left * right
        if operator is ast.Div:
            if right.is_number and right == 0:
                self.refuse("division by zero:", node)
            return left / right
        # ast.Pow
        if right.is_number:
            exponent = complex(right)
            if exponent.imag != 0 or abs(exponent.real) > MAX_EXPONENT:
                self.refuse(f"exponent out of range (|p| <= {MAX_EXPONENT}):", node)
            if left.is_number:
                base = abs(complex(left))
                if base == 0 and exponent.real < 0:
                    self.refuse("zero to a negative power:", node)
                if base > 0 and abs(exponent.real) * abs(math.log10(base)) > MAX_MAGNITUDE_LOG10:
                    self.refuse(f"the power exceeds 1e{MAX_MAGNITUDE_LOG10}:", node)
        return left ** right

    def call(self, node, depth):
        if not isinstance(node.func, ast.Name):
            self.refuse(f"only the functions {sorted(FUNCTIONS)} may be called, not", node.func)
        name = node.func.id
        if name.startswith("_"):
            self.refuse("names starting with '_' are not allowed:", node.func)
        if name not in FUNCTIONS:
            self.refuse(f"unknown function (allowed: {sorted(FUNCTIONS)}):", node.func)
        if node.keywords or any(isinstance(argument, ast.Starred) for argument in node.args):
            self.refuse("functions take positional arguments only:", node)
        function, arity = FUNCTIONS[name]
        if len(node.args) != arity:
            self.refuse(f"{name} takes {arity} argument(s), got {len(node.args)}:", node)
        return function(*[self.convert(argument, depth + 1) for argument in node.args])


def _describe(node):
    kinds = {ast.Attribute: "attribute access", ast.Subscript: "a subscript", ast.Lambda: "a lambda",
             ast.ListComp: "a comprehension", ast.SetComp: "a comprehension", ast.DictComp: "a comprehension",
             ast.GeneratorExp: "a comprehension", ast.Compare: "a comparison", ast.BoolOp: "a boolean operator",
             ast.IfExp: "a conditional", ast.NamedExpr: "an assignment", ast.List: "a list", ast.Tuple: "a tuple",
             ast.Dict: "a dict", ast.Set: "a set", ast.JoinedStr: "a string", ast.Starred: "a starred argument"}
    if isinstance(node, ast.Constant):
        return "a string" if isinstance(node.value, (str, bytes)) else f"a {type(node.value).__name__} constant"
    return kinds.get(type(node), type(node).__name__)
