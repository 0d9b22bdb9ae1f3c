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
it becomes a one-entry list (a scalar gain times I).
"""

import copy
import dataclasses
import hashlib
import itertools
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np
import yaml

from drake_hybrid.scenario.config import dump_config, load_config

GRID_KINDS = ("values", "linspace", "logspace")
RANDOM_KINDS = ("uniform", "loguniform", "normal", "choice")


class SweepSpecError(ValueError):
    """A sweep spec that cannot be run (names the key and what is wrong)."""


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
    """How a point's verdicts are decided (see drake_hybrid.experiments.sweep)."""

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
    source: dict = field(default_factory=dict)           # the YAML as read (saved next to the results)

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


def _number(value, where):
    """YAML 1.1 reads 1e5 (no dot) as a string; accept it as a number."""
    if isinstance(value, bool):
        raise SweepSpecError(f"{where}: expected a number, got {value!r}")
    if isinstance(value, (int, float)):
        return value
    try:
        return float(value)
    except (TypeError, ValueError):
        raise SweepSpecError(f"{where}: expected a number, got {value!r}") from None


def _parse_axis(path, entry):
    where = f"parameters.{path}"
    if isinstance(entry, list):
        entry = {"values": entry}
    if not isinstance(entry, dict) or len(entry) != 1:
        raise SweepSpecError(f"{where}: give exactly one of {GRID_KINDS + RANDOM_KINDS} "
                             f"(e.g. {{values: [1, 2]}} or {{uniform: [0.8, 1.2]}}), got {entry!r}")
    kind, arguments = next(iter(entry.items()))
    if kind not in GRID_KINDS + RANDOM_KINDS:
        raise SweepSpecError(f"{where}: unknown kind '{kind}'; use one of {GRID_KINDS + RANDOM_KINDS}")
    if not isinstance(arguments, list) or not arguments:
        raise SweepSpecError(f"{where}.{kind}: expected a non-empty list, got {arguments!r}")
    if kind in ("values", "choice"):
        arguments = [v if isinstance(v, (list, dict)) else _maybe_number(v) for v in arguments]
    else:
        expected = 3 if kind in ("linspace", "logspace") else 2
        if len(arguments) != expected:
            raise SweepSpecError(f"{where}.{kind}: expected {expected} numbers, got {arguments!r}")
        arguments = [_number(v, f"{where}.{kind}") for v in arguments]
        if kind in ("linspace", "logspace") and not (float(arguments[2]).is_integer() and arguments[2] >= 1):
            raise SweepSpecError(f"{where}.{kind}: the count must be a positive integer, got {arguments[2]}")
        if kind in ("logspace", "loguniform") and not (arguments[0] > 0 and arguments[1] > 0):
            raise SweepSpecError(f"{where}.{kind}: bounds must be positive, got {arguments[:2]}")
        if kind == "uniform" and not arguments[0] <= arguments[1]:
            raise SweepSpecError(f"{where}.uniform: lower bound {arguments[0]} exceeds upper {arguments[1]}")
        if kind == "normal" and not arguments[1] >= 0:
            raise SweepSpecError(f"{where}.normal: the standard deviation must be >= 0, got {arguments[1]}")
    return Axis(path=path, kind=kind, arguments=arguments)


def _maybe_number(value):
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


KNOWN_KEYS = {"task", "base", "parameters", "samples", "seed", "linearize", "stability", "map"}


def parse_spec(data):
    """A SweepSpec from a dict (the YAML's content); SweepSpecError on anything malformed."""
    if not isinstance(data, dict):
        raise SweepSpecError(f"a sweep spec must be a mapping, got {type(data).__name__}")
    unknown = set(data) - KNOWN_KEYS
    if unknown:
        raise SweepSpecError(f"unknown key(s) {sorted(unknown)} in the sweep spec; known: {sorted(KNOWN_KEYS)}")
    parameters = data.get("parameters")
    if not isinstance(parameters, dict) or not parameters:
        raise SweepSpecError("the sweep spec needs 'parameters': a mapping of config paths to values or distributions")
    axes = [_parse_axis(str(path), entry) for path, entry in parameters.items()]
    base = data.get("base") or {}
    if not isinstance(base, dict):
        raise SweepSpecError(f"'base' must be a mapping of config paths to values, got {base!r}")
    overlap = set(base) & set(parameters)
    if overlap:
        raise SweepSpecError(f"{sorted(overlap)} are both in 'base' and in 'parameters'")
    random_axes = [a.path for a in axes if not a.is_grid]
    samples = data.get("samples", 1)
    if not (isinstance(samples, int) and samples >= 1):
        raise SweepSpecError(f"'samples' must be a positive integer, got {samples!r}")
    if "samples" in data and not random_axes:
        raise SweepSpecError("'samples' is given but no parameter has a distribution (uniform, loguniform, "
                             "normal or choice)")
    seed = data.get("seed", 0)
    if not (isinstance(seed, int) and seed >= 0):
        raise SweepSpecError(f"'seed' must be a non-negative integer, got {seed!r}")
    linearize = data.get("linearize", {}) or {}
    unknown = set(linearize) - {"continuous", "discrete"}
    if unknown:
        raise SweepSpecError(f"unknown key(s) {sorted(unknown)} in 'linearize'; known: continuous, discrete")
    stability_data = data.get("stability", {}) or {}
    known = {f.name for f in dataclasses.fields(StabilityCriteria)}
    unknown = set(stability_data) - known
    if unknown:
        raise SweepSpecError(f"unknown key(s) {sorted(unknown)} in 'stability'; known: {sorted(known)}")
    stability = StabilityCriteria(**{k: float(_number(v, f"stability.{k}")) for k, v in stability_data.items()})
    if not 0 < stability.steady_window <= 1:
        raise SweepSpecError(f"stability.steady_window must be in (0, 1], got {stability.steady_window}")
    if not stability.steady_tolerance > 0:
        raise SweepSpecError(f"stability.steady_tolerance must be positive, got {stability.steady_tolerance}")
    map_data = data.get("map", {}) or {}
    for key in ("x", "y", "facet"):
        if key in map_data and map_data[key] not in [a.path for a in axes]:
            raise SweepSpecError(f"map.{key} = '{map_data[key]}' is not one of the parameters {[a.path for a in axes]}")
    return SweepSpec(parameters=axes, base=dict(base), task=data.get("task"), samples=samples, seed=seed,
                     linearize_continuous=bool(linearize.get("continuous", True)),
                     linearize_discrete=bool(linearize.get("discrete", True)),
                     stability=stability, map=dict(map_data), source=copy.deepcopy(data))


def load_spec(path=None, text=None):
    """A SweepSpec from a YAML file or string."""
    if (path is None) == (text is None):
        raise ValueError("give exactly one of path and text")
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise SweepSpecError(f"sweep spec '{path}' does not exist")
        text = path.read_text()
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise SweepSpecError(f"the sweep spec is not valid YAML: {error}") from None
    return parse_spec(data)


# ------------------------------------------------------------------------------------------------
# Dotted paths into a ScenarioConfig
# ------------------------------------------------------------------------------------------------

_SEGMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


def set_config_value(config, path, value):
    """Set ``path`` (e.g. ``contact.pad_modulus``, ``desired_velocity.value[0]``) in ``config`` in place.

    Dataclass fields must exist (ValueError naming the path and the valid
    fields); dict fields (``task_parameters``) accept any key; a scalar for a
    list field becomes a one-entry list."""
    segments = path.split(".")
    target = config
    for depth, segment in enumerate(segments):
        match = _SEGMENT.match(segment)
        if not match:
            raise ValueError(f"config path '{path}': '{segment}' is not a field name (optionally with [index])")
        name, index = match.group(1), match.group(2)
        last = depth == len(segments) - 1
        if isinstance(target, dict):
            if last and index is None:
                target[name] = value
                return
            if name not in target:
                raise ValueError(f"config path '{path}': no key '{name}' in {'.'.join(segments[:depth]) or 'config'}")
            child = target[name]
        elif dataclasses.is_dataclass(target) or hasattr(target, "__fields__"):
            # a config dataclass, or a Drake config struct (MultibodyPlantConfig, SimulatorConfig)
            names = ([f.name for f in dataclasses.fields(target)] if dataclasses.is_dataclass(target)
                     else [f.name for f in target.__fields__])
            if name not in names:
                where = ".".join(segments[:depth]) or "the scenario config"
                raise ValueError(f"config path '{path}': {where} has no field '{name}'; its fields are {names}")
            child = getattr(target, name)
            if last and index is None:
                if isinstance(child, list) and not isinstance(value, list):
                    value = [value]
                setattr(target, name, value)
                return
        else:
            raise ValueError(f"config path '{path}': '{'.'.join(segments[:depth])}' is a value, not a section")
        if index is not None:
            if not isinstance(child, list):
                raise ValueError(f"config path '{path}': '{name}' is not a list, so it takes no [index]")
            position = int(index)
            if position >= len(child):
                raise ValueError(f"config path '{path}': '{name}' has {len(child)} entries, no [{position}]")
            if last:
                child[position] = value
                return
            child = child[position]
        target = child
    raise AssertionError("unreachable")


def apply_parameters(config, parameters):
    """A validated copy of ``config`` with every (path: value) of ``parameters`` set.

    The copy goes through the config's YAML (``dump_config`` / ``load_config``),
    which checks every value's type, so a point is exactly what a worker gets."""
    point = copy.deepcopy(config)
    for path, value in parameters.items():
        set_config_value(point, path, value)
    try:
        return load_config(data=dump_config(point))
    except Exception as error:   # Drake's typed YAML raises RuntimeError on a type mismatch
        raise ValueError(f"parameters {parameters} do not give a valid scenario config: {error}") from None


def parameters_digest(points):
    """A short digest of the points (to check that --resume continues the same sweep)."""
    return hashlib.sha256(json.dumps(points, sort_keys=True, default=str).encode()).hexdigest()[:16]
