"""Checking the arguments of the package's public constructors and functions, one way.

Every public constructor and function checks its arguments at the call with these helpers, so bad
input ends in the same kind of message wherever it is given::

    HybridController: control_period must be a positive finite number (s) or None, got inf
    HybridGains: null_space_damping must be a finite number >= 0 (1/s), got 'x' (a str)
    CustomTask: add_robot must be a callable add_robot(plant) -> RobotModel, got None

One line, a typed error of the ``DrakeHybridError`` family (``ArgumentError`` unless the caller
names another, e.g. ``GainError`` for gains), naming the callee, the argument, what it got and what
is allowed. Types come before values (a string is refused, not parsed: "0.001" is not a period),
shapes before entries (a matrix where a vector is meant is called a matrix, with its size), and NaN
and inf are refused unless the argument allows inf.
"""

import math
import numbers
from typing import Any, Collection, Optional, Tuple, Type

import numpy as np

from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array

_SHOWN_ENTRIES = 9          # an array with more entries is described by its shape only
MAX_TASK_SIZE = 6           # the most coordinates a task has (a pose's d): a bound on k and m


def _entries(array):
    return "[" + ", ".join(f"{entry:g}" for entry in np.asarray(array, dtype=float).reshape(-1)) + "]"


def describe(value: Any) -> str:
    """What an argument holds, in a few words for a message: a number as it prints, a string quoted,
    an array by its shape (and its entries when there are few), another object by its type."""
    if value is None:
        return "None"
    if isinstance(value, (bool, np.bool_)):
        return f"{bool(value)} (a bool)"
    if isinstance(value, numbers.Integral):
        return f"{int(value)}"
    if isinstance(value, numbers.Real):
        return f"{float(value):g}"
    if isinstance(value, str):
        text = value if len(value) <= 40 else value[:37] + "..."
        return f"{text!r} (a str)"
    if isinstance(value, (list, tuple, np.ndarray)):
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            text = repr(value)
            text = text if len(text) <= 60 else text[:57] + "..."
            return f"{text} (a {type(value).__name__} with non-numeric or ragged entries)"
        shown = _entries(array) if array.size <= _SHOWN_ENTRIES else ""
        if array.ndim == 0:
            return f"{float(array):g}"
        if array.ndim == 1:
            return f"{shown} (a vector of {array.size})" if shown else f"a vector of {array.size} entries"
        if array.ndim == 2:
            return f"a {array.shape[0]}x{array.shape[1]} matrix" + (f" {shown}" if shown else "")
        return f"an array of shape {array.shape}"
    return f"a {type(value).__name__}"


def _fail(error, owner, name, allowed, value):
    raise error(f"{owner}: {name} must be {allowed}, got {describe(value)}")


def _range_words(low, high, low_inclusive, high_inclusive):
    words = []
    if low is not None:
        words.append(f"{'>=' if low_inclusive else '>'} {low:g}")
    if high is not None:
        words.append(f"{'<=' if high_inclusive else '<'} {high:g}")
    return " and ".join(words)


def number(value, name, owner, *, low=None, high=None, low_inclusive=True, high_inclusive=True, allow_none=False,
           allow_infinite=False, integer=False, unit="", error=ArgumentError):
    """``value`` as a float (an int with ``integer``; None if ``allow_none`` and it is None), checked:
    a real number (not a bool, a string or a sequence), finite (unless ``allow_infinite``; NaN never),
    within [``low``, ``high``] (each bound open unless inclusive). ``unit``: for the message."""
    range_text = _range_words(low, high, low_inclusive, high_inclusive)
    allowed = (("a " if allow_infinite else "a finite ") + ("integer" if integer else "number")
               + (f" {range_text}" if range_text else "") + (f" ({unit})" if unit else "")
               + (" or None" if allow_none else ""))
    if value is None and allow_none:
        return None
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        _fail(error, owner, name, allowed, value)
    number_ = float(value)
    if math.isnan(number_) or (math.isinf(number_) and not allow_infinite):
        _fail(error, owner, name, allowed, value)
    if integer and not (math.isfinite(number_) and number_.is_integer()):
        _fail(error, owner, name, allowed, value)
    if low is not None and not (number_ >= low if low_inclusive else number_ > low):
        _fail(error, owner, name, allowed, value)
    if high is not None and not (number_ <= high if high_inclusive else number_ < high):
        _fail(error, owner, name, allowed, value)
    return int(number_) if integer else number_


def positive(value, name, owner, *, unit="", allow_none=False, allow_infinite=False, error=ArgumentError):
    """``number`` > 0."""
    return number(value, name, owner, low=0.0, low_inclusive=False, unit=unit, allow_none=allow_none,
                  allow_infinite=allow_infinite, error=error)


def nonnegative(value, name, owner, *, unit="", allow_none=False, error=ArgumentError):
    """``number`` >= 0."""
    return number(value, name, owner, low=0.0, unit=unit, allow_none=allow_none, error=error)


def numeric_array(value: Any, name: str, owner: str, *, what: str = "a number, a vector or a matrix",
                  finite: bool = True, error: Type[Exception] = ArgumentError) -> Array:
    """``value`` as a float ndarray of any shape: numbers only (no None, string, mapping, bool entries or
    ragged nesting), finite unless ``finite`` is False (NaN always refused)."""
    allowed = what + (" of finite numbers" if finite and what.endswith(("vector", "matrix")) else "")
    if value is None or isinstance(value, (str, bytes, dict)) or isinstance(value, (bool, np.bool_)):
        _fail(error, owner, name, allowed, value)
    if not isinstance(value, (numbers.Real, list, tuple, np.ndarray)):
        _fail(error, owner, name, allowed, value)
    if isinstance(value, (list, tuple)) and any(isinstance(entry, (bool, np.bool_, str)) for entry in _flat(value)):
        _fail(error, owner, name, allowed, value)
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        _fail(error, owner, name, allowed, value)
    if np.any(np.isnan(array)) or (finite and not np.all(np.isfinite(array))):
        _fail(error, owner, name, allowed if finite else allowed + " (no NaN)", value)
    return array


def _flat(value):
    for entry in value:
        if isinstance(entry, (list, tuple)):
            yield from _flat(entry)
        else:
            yield entry


def vector(value: Any, name: str, owner: str, size: Optional[int] = None, *, unit: str = "", finite: bool = True,
           error: Type[Exception] = ArgumentError) -> Array:
    """``value`` as a 1-D float ndarray (of ``size`` entries if given): a number where a vector is
    meant, or a matrix, is refused naming what it is."""
    count = f"{size} " if size is not None else ""
    allowed = f"a vector of {count}{'finite ' if finite else ''}numbers" + (f" ({unit})" if unit else "")
    array = numeric_array(value, name, owner, what=allowed, finite=finite, error=error)
    if array.ndim != 1 or (size is not None and array.size != size):
        _fail(error, owner, name, allowed, value)
    return array


_JOINT_KINDS = {"positions": ("num_positions", "joint positions, rad or m"),
                "velocities": ("num_velocities", "joint velocities, rad/s or m/s"),
                "actuators": ("num_actuated_dofs", "actuation, N m or N")}


def joint_vector(value: Any, name: str, owner: str, plant: Any, model_instance: Any = None, *, kind: str = "positions",
                 unit: Optional[str] = None, error: Type[Exception] = ArgumentError) -> Array:
    """``value`` as a vector of ``plant``'s number of finite ``kind`` ("positions", "velocities" or
    "actuators"; those of ``model_instance`` if given): the check before a user's vector reaches Drake's
    SetPositions / SetVelocities / SetPositionsAndVelocities or an actuation port, which end the process
    (an assertion, no exception) on a wrong size or a NaN. ``unit`` replaces the kind's own words."""
    count, words = _joint_count(plant, model_instance, kind)
    return vector(value, name, owner, count, unit=unit or words, error=error)


def joint_rows(value: Any, name: str, owner: str, plant: Any, model_instance: Any = None, *, kind: str = "positions",
               unit: Optional[str] = None, error: Type[Exception] = ArgumentError) -> Array:
    """``value`` as a 2-D float array whose rows are each a ``joint_vector`` (a log's q or v, one row a sample)."""
    count, words = _joint_count(plant, model_instance, kind)
    allowed = f"a matrix of rows of {count} finite numbers ({unit or words})"
    array = numeric_array(value, name, owner, what=allowed, error=error)
    if array.ndim != 2 or array.shape[1] != count:
        _fail(error, owner, name, allowed, value)
    return array


def _joint_count(plant, model_instance, kind):
    method, words = _JOINT_KINDS[kind]
    return (getattr(plant, method)() if model_instance is None else getattr(plant, method)(model_instance)), words


def matrix(value: Any, name: str, owner: str, shape: Tuple[int, int], *, finite: bool = True,
           error: Type[Exception] = ArgumentError) -> Array:
    """``value`` as a float ndarray of ``shape`` (rows, columns)."""
    allowed = f"a {shape[0]}x{shape[1]} matrix of {'finite ' if finite else ''}numbers"
    array = numeric_array(value, name, owner, what=allowed, finite=finite, error=error)
    if array.shape != tuple(shape):
        _fail(error, owner, name, allowed, value)
    return array


def boolean(value: Any, name: str, owner: str, *, error: Type[Exception] = ArgumentError) -> bool:
    """``value`` as a bool: True or False only (not 0, 1 or "yes")."""
    if not isinstance(value, (bool, np.bool_)):
        _fail(error, owner, name, "True or False", value)
    return bool(value)


def text(value: Any, name: str, owner: str, *, allowed: Optional[Collection[str]] = None,
         error: Type[Exception] = ArgumentError) -> str:
    """``value`` as a str (one of ``allowed`` if given)."""
    words = f"one of {', '.join(repr(word) for word in allowed)}" if allowed else "a string"
    if not isinstance(value, str) or (allowed and value not in allowed):
        _fail(error, owner, name, words, value)
    return value


def function(value, name, owner, signature, *, allow_none=False, error=ArgumentError):
    """``value`` if it is callable (None if ``allow_none``); ``signature`` says how it is called."""
    if value is None and allow_none:
        return None
    if not callable(value):
        _fail(error, owner, name, f"a callable {signature}" + (" or None" if allow_none else ""), value)
    return value


def instance(value, name, owner, kinds, *, what=None, allow_none=False, error=ArgumentError):
    """``value`` if it is an instance of ``kinds`` (None if ``allow_none``); ``what``: how to say the
    allowed kinds (default: their names)."""
    if value is None and allow_none:
        return None
    if not isinstance(value, kinds):
        names = what or " or ".join(f"a {kind.__name__}" for kind in (kinds if isinstance(kinds, tuple) else (kinds,)))
        _fail(error, owner, name, names + (" or None" if allow_none else ""), value)
    return value


def relative_tolerance(value: Any, name: str, owner: str, *, error: Type[Exception] = ArgumentError) -> float:
    """``number`` in (0, 1]: a relative tolerance (0.05: within 5 %), as ``drake-hybrid analyze --tolerance``
    and ``analysis.matching`` and the linearizations take it (0, NaN, a negative one or one above 1 would give a
    verdict that means nothing)."""
    return number(value, name, owner, low=0.0, low_inclusive=False, high=1.0, unit="relative: 0.05 is within 5 %",
                  error=error)


def complex_vector(value: Any, name: str, owner: str, *, nonzero: bool = False,
                   error: Type[Exception] = ArgumentError) -> Array:
    """``value`` as a 1-D complex ndarray (eigenvalues): real or complex numbers only (no string, bool or
    None entries), finite, and none zero if ``nonzero``."""
    allowed = "a vector of finite " + ("nonzero " if nonzero else "") + "real or complex numbers"
    entries = np.ravel(value) if isinstance(value, np.ndarray) else value
    if not isinstance(entries, (list, tuple, np.ndarray)) or not all(
            isinstance(entry, numbers.Number) and not isinstance(entry, (bool, np.bool_)) for entry in entries):
        _fail(error, owner, name, allowed, value)
    array = np.asarray(value, dtype=complex)
    if array.ndim != 1 or not np.all(np.isfinite(array)) or (nonzero and np.any(array == 0)):
        _fail(error, owner, name, allowed, value)
    return array
