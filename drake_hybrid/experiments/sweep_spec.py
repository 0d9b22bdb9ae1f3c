"""Sweep specifications: which scenario-config fields to vary, and how (YAML).

A spec names config fields by dotted path (``contact.pad_modulus``,
``gains.force_proportional``, ``control_period``,
``task_parameters.window_height``, ``model_error.payload_mass_scale``; a list
entry as ``desired_velocity.value[0]``) and gives each either grid values or a
distribution::

    task: window-washing              # optional; must match the sweep's TASK
    base:                             # overrides of the task's default config, applied first
      duration: 1.0
      start.tolerance: 0.02
    parameters:
      contact.pad_modulus: {logspace: [1.0e5, 1.0e9, 9]}     # grid axes: values / linspace / logspace
      gains.force_proportional: {values: [0.25, 0.5, 1, 2]}
      control_period: {values: [0.001, 0.004]}
      model_error.payload_mass_scale: {uniform: [0.8, 1.2]}  # random axes: uniform / loguniform / normal / choice
    samples: 50                       # random draws per grid point (needed when a random axis is given)
    seed: 7                           # fixed seed of the random draws
    linearize: {continuous: true, discrete: true}
    stability: {steady_window: 0.2, steady_tolerance: 0.05, eigenvalue_margin: 0.0}
    map: {x: contact.pad_modulus, y: gains.force_proportional, facet: control_period}

The points are the Cartesian product of the grid axes (in the order given,
the last one varying fastest), each with ``samples`` draws of the random axes
(numpy ``default_rng(seed)``, drawn point by point in axis order): the same
spec always gives the same points, in the same order, on any machine.

A value for a list field (the gains are stored as flat lists) may be a scalar:
it becomes a one-entry list (a scalar gain times I); set one entry of a list
with an index (``gains.velocity[1]``).

The YAML is loaded with Drake's ``yaml_load_typed`` on ``SweepSpecFile``: an
unknown key or a wrong type is an error naming it. Every parameter names its
kind (``{values: [...]}``, not a bare list). The numbers of the spec itself are
checked at load (finite, in range); its values against the task's config when the
sweep starts (``check_axis_values``: each like the config field it sets). Paths
into the config are ``experiments.config_paths``.
"""

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Union

import numpy as np
import yaml

from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

from drake_hybrid.core.errors import DrakeHybridError
from drake_hybrid.core.schema import check_yaml_against_schema, read_yaml_file
from drake_hybrid.experiments.config_paths import apply_parameters, config_value
from drake_hybrid.scenario.builder import prepare_config

GRID_KINDS = ("values", "linspace", "logspace")
RANDOM_KINDS = ("uniform", "loguniform", "normal", "choice")


class SweepSpecError(DrakeHybridError):
    """A sweep spec that cannot be run (names the key and what is wrong); a ``ValueError``, as every error
    of the package's (``core.errors``)."""


@dataclass
class Axis:
    """One varied config field: grid values, or a distribution to draw from."""

    path: str
    kind: str                        # one of GRID_KINDS + RANDOM_KINDS
    arguments: list

    @property
    def is_grid(self):
        return self.kind in GRID_KINDS

    def grid_values(self):
        a = self.arguments
        if self.kind == "values":
            return list(a)
        if self.kind == "linspace":
            return [float(v) for v in np.linspace(a[0], a[1], int(a[2]))]
        return [float(v) for v in np.logspace(math.log10(a[0]), math.log10(a[1]), int(a[2]))]

    def draw(self, rng):
        a = self.arguments
        if self.kind == "uniform":
            return float(rng.uniform(a[0], a[1]))
        if self.kind == "loguniform":
            return float(math.exp(rng.uniform(math.log(a[0]), math.log(a[1]))))
        if self.kind == "normal":
            return float(rng.normal(a[0], a[1]))
        return a[int(rng.integers(len(a)))]


@dataclass
class StabilityCriteria:
    """How a point's verdicts are decided (see drake_hybrid.experiments.sweep_point)."""

    steady_window: float = 0.2       # last fraction of the horizon where the steady errors are measured
    steady_tolerance: float = 0.05   # settled: max error there <= this fraction of the command
    eigenvalue_margin: float = 0.0   # stable linearization: worst non-marginal Re(s) < this (1/s)


@dataclass
class SweepSpec:
    parameters: List[Axis]
    base: Dict[str, object] = field(default_factory=dict)
    task: Optional[str] = None
    samples: int = 1
    seed: int = 0
    linearize_continuous: bool = True
    linearize_discrete: bool = True
    stability: StabilityCriteria = field(default_factory=StabilityCriteria)
    map: Dict[str, str] = field(default_factory=dict)
    source: dict = field(default_factory=dict)           # the spec as loaded, every field (saved with the results)

    @property
    def paths(self):
        return [axis.path for axis in self.parameters]

    def points(self):
        """The parameter dicts of every point, in order (deterministic; see the module docstring)."""
        grid = [axis for axis in self.parameters if axis.is_grid]
        random_axes = [axis for axis in self.parameters if not axis.is_grid]
        rng = np.random.default_rng(self.seed)
        draws = self.samples if random_axes else 1
        points = []
        for combination in itertools.product(*[axis.grid_values() for axis in grid]):
            fixed = dict(zip([axis.path for axis in grid], combination))
            for _ in range(draws):
                point = dict(fixed)
                for axis in random_axes:
                    point[axis.path] = axis.draw(rng)
                points.append({path: point[path] for path in self.paths})
        return points


# ------------------------------------------------------------------------------------------------
# The YAML schema (loaded with Drake's typed YAML: unknown keys and wrong types are errors)
# ------------------------------------------------------------------------------------------------

@dataclass
class AxisSpec:
    """One parameter: exactly one kind, with its list of arguments (see the module docstring)."""

    values: List[Union[float, bool, str]] = field(default_factory=list)   # grid: the values themselves
    linspace: List[float] = field(default_factory=list)               # grid: [start, stop, count]
    logspace: List[float] = field(default_factory=list)               # grid: [start, stop, count], start > 0
    uniform: List[float] = field(default_factory=list)                # random: [low, high]
    loguniform: List[float] = field(default_factory=list)             # random: [low, high], both > 0
    normal: List[float] = field(default_factory=list)                 # random: [mean, standard deviation]
    choice: List[Union[float, bool, str]] = field(default_factory=list)   # random: one of the values


@dataclass
class LinearizeSpec:
    """Which linearizations each point gets."""

    continuous: bool = True
    discrete: bool = True


@dataclass
class MapSpec:
    """The stability map's axes: parameter paths (empty: no map); color: a results column."""

    x: str = ""
    y: str = ""
    facet: str = ""
    color: str = ""


@dataclass
class SweepSpecFile:
    """A sweep spec as written in YAML (``load_spec`` turns it into a ``SweepSpec``)."""

    task: str = ""
    base: Dict[str, Union[float, bool, str]] = field(default_factory=dict)
    parameters: Dict[str, AxisSpec] = field(default_factory=dict)
    samples: int = 1
    seed: int = 0
    linearize: LinearizeSpec = field(default_factory=LinearizeSpec)
    stability: StabilityCriteria = field(default_factory=StabilityCriteria)
    map: MapSpec = field(default_factory=MapSpec)
    max_points: int = 10000          # refuse larger sweeps unless raised here (a typo in a count is costly)


def _number(value, where):
    """YAML 1.1 reads 1e5 (no dot) as a string; accept it as a number."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SweepSpecError(f"{where}: expected a number, got {value!r}") from None


def _maybe_number(value):
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def _axis(path, entry):
    """An Axis from one ``AxisSpec``, its arguments checked for its kind."""
    where = f"parameters.{path}"
    given = [(kind, getattr(entry, kind)) for kind in GRID_KINDS + RANDOM_KINDS if getattr(entry, kind)]
    if len(given) != 1:
        raise SweepSpecError(f"{where}: give exactly one non-empty kind of {GRID_KINDS + RANDOM_KINDS} "
                             f"(e.g. {{values: [1, 2]}} or {{uniform: [0.8, 1.2]}}), got {[k for k, _ in given]}")
    kind, arguments = given[0]
    if kind in ("values", "choice"):
        return Axis(path=path, kind=kind, arguments=[_maybe_number(v) for v in arguments])
    expected = 3 if kind in ("linspace", "logspace") else 2
    if len(arguments) != expected:
        raise SweepSpecError(f"{where}.{kind}: expected {expected} numbers, got {arguments!r}")
    for index, argument in enumerate(arguments):
        if not math.isfinite(argument):
            raise SweepSpecError(f"{where}.{kind}[{index}]: expected a finite number, got {argument}")
    if kind in ("linspace", "logspace") and not (float(arguments[2]).is_integer() and arguments[2] >= 1):
        raise SweepSpecError(f"{where}.{kind}: the count must be a positive integer, got {arguments[2]}")
    if kind in ("logspace", "loguniform") and not (arguments[0] > 0 and arguments[1] > 0):
        raise SweepSpecError(f"{where}.{kind}: bounds must be positive, got {arguments[:2]}")
    if kind == "uniform" and not arguments[0] <= arguments[1]:
        raise SweepSpecError(f"{where}.uniform: lower bound {arguments[0]:g} exceeds upper {arguments[1]:g}")
    if kind == "normal" and not arguments[1] >= 0:
        raise SweepSpecError(f"{where}.normal: the standard deviation must be >= 0, got {arguments[1]}")
    return Axis(path=path, kind=kind, arguments=list(arguments))


def _point_count(axes, samples):
    """How many points the axes give (without generating them)."""
    count = 1
    for axis in axes:
        if axis.is_grid:
            count *= len(axis.arguments) if axis.kind == "values" else int(axis.arguments[2])
    return count * (samples if any(not axis.is_grid for axis in axes) else 1)


def parse_spec(spec_file):
    """A SweepSpec from a ``SweepSpecFile`` (checks what the types cannot: SweepSpecError naming the key)."""
    if not spec_file.parameters:
        raise SweepSpecError("the sweep spec needs 'parameters': a mapping of config paths to values or distributions")
    axes = [_axis(path, entry) for path, entry in spec_file.parameters.items()]
    if not spec_file.samples >= 1:
        raise SweepSpecError(f"'samples' must be a positive integer, got {spec_file.samples}")
    if spec_file.samples != 1 and all(axis.is_grid for axis in axes):
        raise SweepSpecError("'samples' is given but no parameter has a distribution (uniform, loguniform, "
                             "normal or choice)")
    if not spec_file.seed >= 0:
        raise SweepSpecError(f"'seed' must be a non-negative integer, got {spec_file.seed}")
    stability = spec_file.stability
    if not math.isfinite(stability.eigenvalue_margin):
        raise SweepSpecError(f"stability.eigenvalue_margin must be a finite number (1/s), got "
                             f"{stability.eigenvalue_margin}")
    if not 0 < stability.steady_window <= 1:
        raise SweepSpecError(f"stability.steady_window must be in (0, 1], got {stability.steady_window}")
    if not 0 < stability.steady_tolerance < math.inf:
        raise SweepSpecError(f"stability.steady_tolerance must be positive and finite, got {stability.steady_tolerance}")
    paths = [axis.path for axis in axes]
    for path in paths:
        for other in paths:
            if other != path and (other.startswith(path + ".") or other.startswith(path + "[")):
                raise SweepSpecError(f"parameters '{path}' and '{other}' set the same field; keep one")
        if path in spec_file.base or any(key.startswith(path + ".") or key.startswith(path + "[")
                                         or path.startswith(key + ".") or path.startswith(key + "[")
                                         for key in spec_file.base):
            raise SweepSpecError(f"parameter '{path}' overlaps a field set in 'base'; keep one")
    count = _point_count(axes, spec_file.samples)
    if count > spec_file.max_points:
        raise SweepSpecError(f"the sweep has {count} points, more than max_points = {spec_file.max_points}; "
                             "raise max_points in the spec if that is intended")
    map_data = {key: getattr(spec_file.map, key) for key in ("x", "y", "facet", "color")
                if getattr(spec_file.map, key)}
    for key in ("x", "y", "facet"):
        if key in map_data and map_data[key] not in paths:
            raise SweepSpecError(f"map.{key} = '{map_data[key]}' is not one of the parameters {paths}")
    return SweepSpec(parameters=axes, base={path: _maybe_number(v) for path, v in spec_file.base.items()},
                     task=spec_file.task or None, samples=spec_file.samples, seed=spec_file.seed,
                     linearize_continuous=spec_file.linearize.continuous,
                     linearize_discrete=spec_file.linearize.discrete, stability=stability, map=map_data,
                     source=yaml.safe_load(yaml_dump_typed(spec_file)))


def load_spec(path=None, text=None):
    """A SweepSpec from a YAML file or string, loaded with Drake's ``yaml_load_typed`` on
    ``SweepSpecFile``; any error is one SweepSpecError line naming the key."""
    if (path is None) == (text is None):
        raise ValueError("give exactly one of path and text")
    where = "the sweep spec"
    if path is not None:
        text, where = read_yaml_file(path, "sweep spec", error=SweepSpecError), f"sweep spec '{path}'"
    parsed = check_yaml_against_schema(text, SweepSpecFile, f"{where}: ", error=SweepSpecError)
    if not isinstance(parsed, dict):
        raise SweepSpecError(f"{where}: a sweep spec is a YAML mapping with 'parameters' (docs/stability.md), got "
                             f"{type(parsed).__name__ if parsed is not None else 'nothing'}")
    try:
        spec_file = yaml_load_typed(schema=SweepSpecFile, data=text)
    except (AssertionError, RuntimeError, ValueError, TypeError) as error:
        raise SweepSpecError(f"{where}: {str(error).splitlines()[0]}") from None
    except yaml.YAMLError as error:
        raise SweepSpecError(f"{where} is not valid YAML: {str(error).splitlines()[0]}") from None
    return parse_spec(spec_file)


# ------------------------------------------------------------------------------------------------
# The values of a spec, checked like the config fields they set
# ------------------------------------------------------------------------------------------------

def _field_allows(current, value):
    """Whether ``value`` has a type the config field now holding ``current`` takes (YAML's rules: a bool
    field takes true or false, a number field numbers, a word field words, a list field a number or a list)."""
    if isinstance(current, bool):
        return isinstance(value, bool)
    if isinstance(current, (int, float)):
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if isinstance(current, str):
        return isinstance(value, str)
    if isinstance(current, list):
        entries = value if isinstance(value, list) else [value]
        return all(isinstance(entry, (int, float)) and not isinstance(entry, bool) for entry in entries)
    return True


def check_axis_values(spec, base):
    """SweepSpecError naming ``parameters.PATH.KIND[i]`` for a value of an axis that its config field does
    not take, checked like a config field: its type, then the config with that value alone set on ``base``
    as a build checks it (``scenario.builder.prepare_config``: every field, the task's options, the gains
    against the task's sizes). Grid values and choices are checked one by one, a distribution by its bounds
    (uniform, loguniform) or its mean (normal)."""
    for axis in spec.parameters:
        if axis.kind in ("values", "choice"):
            candidates = list(enumerate(axis.arguments))
        elif axis.kind in ("linspace", "logspace", "uniform", "loguniform"):
            candidates = [(0, float(axis.arguments[0])), (1, float(axis.arguments[1]))]
        else:
            candidates = [(0, float(axis.arguments[0]))]
        try:
            current = config_value(base, axis.path)
        except ValueError as error:
            raise SweepSpecError(f"parameters.{axis.path}: {error}") from None
        for index, value in candidates:
            where = f"parameters.{axis.path}.{axis.kind}[{index}] = {value!r}"
            if not _field_allows(current, value):
                kind = ("true or false" if isinstance(current, bool) else "a word" if isinstance(current, str)
                        else "a number")
                raise SweepSpecError(f"{where}: {axis.path} takes {kind}, like {current!r}")
            try:
                prepare_config(apply_parameters(base, {axis.path: value}))
            except ValueError as error:
                message = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
                raise SweepSpecError(f"{where}: {message}") from None


def parameters_digest(points):
    """A short digest of the points (to check that --resume continues the same sweep)."""
    return hashlib.sha256(json.dumps(points, sort_keys=True, default=str).encode()).hexdigest()[:16]
