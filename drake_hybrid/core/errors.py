"""Typed errors raised by drake_hybrid.

Every error is a ``ValueError`` subclass, so callers that do not care about the
kind can catch ``ValueError``; tests and users that do care can catch the
specific type. Messages always name the offending object and the numbers.
"""

import dataclasses
import math
from typing import Collection, Iterable, Type, TypeVar

_Owner = TypeVar("_Owner")


class DrakeHybridError(ValueError):
    """Base class of every error raised on purpose by drake_hybrid."""


class ConfigError(DrakeHybridError):
    """A configuration field has a value (or a name, or a type) that is not allowed; the message
    names the field (dotted, as in the YAML) and what is allowed."""


class ArgumentError(DrakeHybridError):
    """An argument of a public constructor or function has a type, shape or value that is not
    allowed; the message names the callee and the argument, what it got and what is allowed
    (``core.arguments`` checks every argument the same way)."""


class ChartSingularityError(DrakeHybridError):
    """A coordinate chart was evaluated at (or too near) its singular set.

    For z-x-z Euler angles this is |sin(theta)| below the chart's tolerance,
    where the Euler-rate map T(eta) loses rank (docs/theory.md §1).
    """


class ConstraintRankError(DrakeHybridError):
    """dC (the force projection E_f) lost rank, or E = [E_p; E_f] is singular."""


class UnknownVariableError(DrakeHybridError):
    """A symbolic expression uses variables that are not the chart's coordinates."""


class ExpressionError(DrakeHybridError):
    """A symbolic expression cannot be compiled: a non-finite constant (nan, oo, zoo) or a function the
    generated code does not evaluate; the message names the expression and what is allowed."""


class CodeGenerationError(DrakeHybridError):
    """Generated code disagrees with sympy's own evaluation of the expression it was generated from
    (checked when it is compiled); the message names the term, the point and both values. It means a
    defect of drake_hybrid's code generator: please report it with the expression."""


class DimensionError(DrakeHybridError):
    """An array has the wrong shape for the object it is given to."""


class GainError(DrakeHybridError):
    """A gain matrix is not of the right size or not positive definite."""


class BranchError(DrakeHybridError):
    """A configuration satisfies C(r) = 0 on the wrong branch (e.g. the tool
    pointing away from the workpiece instead of toward it)."""


class MissingExtraError(DrakeHybridError, ImportError):
    """An optional dependency is not installed: the message names the extra that installs it (e.g.
    sweeps on a Dask cluster need ``pip install 'drake-hybrid[cluster]'``). Also an ImportError, so
    that code catching a failed import catches it."""


class KinematicSingularityWarning(UserWarning):
    """The arm is near a kinematic singularity: the controller bounds the joint acceleration with a
    damped inverse of J there, so the commanded task acceleration is only approximately produced."""


class OffConstraintError(DrakeHybridError):
    """A configuration that should satisfy C(r) = 0 does not (e.g. a start
    configuration off the constraint)."""


class NotAtEquilibriumError(OffConstraintError):
    """A linearization was asked at a state that is not an equilibrium of the closed loop (max |x-dot|
    beyond the tolerance relative to the state's size), where its eigenvalues say nothing about the
    design; the message names the residual, the system it is largest in and the likely cause (a
    commanded motion, a start not solved, a sensor whose reading is not the contact's at rest)."""


class StartCollisionError(OffConstraintError):
    """At the start, a part of the robot other than its tool penetrates the workpiece or the scene
    (the collision filters that let only the tool touch hide it from the simulation); the message
    names the bodies and the geometries."""


class UnknownFrameError(DrakeHybridError):
    """A frame named by the user (a flange, a tool frame) is not in the model; the message lists
    the model's frames."""


class UnreachablePoseError(DrakeHybridError):
    """No joint positions within the joint limits put the end effector at the requested pose."""


class ForceSignError(DrakeHybridError):
    """The desired force pulls on the workpiece: F_d is the force ON the robot in E_f's coordinates,
    and a contact can only push, so along the pressing direction -sum_i F_d,i grad C_i the pad must
    go into the workpiece."""


def check_fields(owner: _Owner, prefix: str, positive: Iterable[str] = (), nonnegative: Iterable[str] = (),
                 error: Type[Exception] = ConfigError) -> _Owner:
    """Raise ``error`` (ConfigError) naming ``prefix.field`` if a field of ``owner`` (a config dataclass)
    listed in ``positive`` is not > 0 or one in ``nonnegative`` is not >= 0 (NaN fails both)."""
    for names, test, words in ((positive, lambda x: x > 0, "positive"), (nonnegative, lambda x: x >= 0, ">= 0")):
        for name in names:
            number = getattr(owner, name)
            if not test(float(number)):
                raise error(f"{prefix}{name} must be {words}, got {number}")
    return owner


def check_finite(owner: _Owner, prefix: str = "", allow_infinite: Collection[str] = ()) -> _Owner:
    """Raise ConfigError naming the field for a NaN anywhere among the numbers of a config
    dataclass (its fields, lists, dicts and nested config dataclasses), and for +-inf except in the
    fields named (dotted, relative to ``owner``) in ``allow_infinite``. Other objects (e.g. Drake's
    config structs, checked by their own validators) are skipped."""
    def walk(value, name):
        if isinstance(value, bool) or value is None:
            return
        if isinstance(value, (int, float)):
            if math.isnan(value) or (math.isinf(value) and name.split("[")[0] not in allow_infinite):
                allowed = "a finite number" + (" or inf" if name.split("[")[0] in allow_infinite else "")
                raise ConfigError(f"{prefix}{name} must be {allowed}, got {value}")
        elif isinstance(value, (list, tuple)):
            for index, item in enumerate(value):
                walk(item, f"{name}[{index}]")
        elif isinstance(value, dict):
            for key, item in value.items():
                walk(item, f"{name}.{key}")
        elif dataclasses.is_dataclass(value):
            for item in dataclasses.fields(value):
                walk(getattr(value, item.name), f"{name}.{item.name}" if name else item.name)

    walk(owner, "")
    return owner


class PathError(DrakeHybridError):
    """A path or a coverage pattern that the controller cannot follow: a waypoint off the workpiece's
    surface by more than the tolerance, a limit that is not positive, a pattern outside the region
    where the surface is defined, a height map with missing or too few samples. The message names
    the field (or the waypoint) and what is allowed."""
