"""Dotted paths into a ScenarioConfig: read a field, set it, apply a sweep point's parameters.

A path names a field as a sweep spec does (``contact.pad_modulus``, ``gains.force_proportional``,
``task_parameters.window_height``, a list entry as ``desired_velocity.value[0]``): config dataclasses,
Drake's config structs (``plant.time_step``) and dicts (a dict takes any key as its last segment).
``set_config_value`` turns a scalar for a list field into a one-entry list (a scalar gain times I).
"""

import copy
import dataclasses
import re

from drake_hybrid.tasks.config import dump_config, load_config

_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?")     # the whole segment (fullmatch)


def _fields(target):
    """The field names of a config dataclass or a Drake config struct (None for anything else)."""
    if dataclasses.is_dataclass(target):
        return [f.name for f in dataclasses.fields(target)]
    if hasattr(target, "__fields__"):          # MultibodyPlantConfig, SimulatorConfig
        return [f.name for f in target.__fields__]
    return None


def _locate(config, path):
    """(section, name, index) of the field ``path`` names in ``config``: the dataclass, Drake struct or dict
    holding it, the field's name and its [index] (None); ValueError naming the path if there is none. A dict
    (``task_parameters``) takes any key as its last segment."""
    segments = path.split(".")
    target = config
    for depth, segment in enumerate(segments):
        match = _SEGMENT.fullmatch(segment)
        if not match:
            raise ValueError(f"config path '{path}': '{segment}' is not a field name (optionally with [index])")
        name, index = match.group(1), match.group(2)
        index = None if index is None else int(index)
        names = _fields(target)
        if isinstance(target, dict):
            if name not in target and not (depth == len(segments) - 1 and index is None):
                raise ValueError(f"config path '{path}': no key '{name}' in {'.'.join(segments[:depth]) or 'config'}")
        elif names is not None:
            if name not in names:
                where = ".".join(segments[:depth]) or "the scenario config"
                raise ValueError(f"config path '{path}': {where} has no field '{name}'; its fields are "
                                 f"{', '.join(names)}")
        else:
            raise ValueError(f"config path '{path}': '{'.'.join(segments[:depth])}' is a value, not a section")
        if depth == len(segments) - 1:
            if index is not None:
                _entry(path, name, _read(target, name), index)
            return target, name, index
        child = _read(target, name)
        target = child if index is None else _entry(path, name, child, index)
    raise AssertionError("unreachable")


def _read(section, name):
    return section.get(name) if isinstance(section, dict) else getattr(section, name)


def _entry(path, name, child, index):
    if not isinstance(child, list):
        raise ValueError(f"config path '{path}': '{name}' is not a list, so it takes no [index]")
    if index >= len(child):
        raise ValueError(f"config path '{path}': '{name}' has {len(child)} entries, no [{index}]")
    return child[index]


def set_config_value(config, path, value):
    """Set ``path`` (e.g. ``contact.pad_modulus``, ``desired_velocity.value[0]``) in ``config`` in place.

    Dataclass fields must exist (ValueError naming the path and the valid
    fields); dict fields (``task_parameters``) accept any key; a scalar for a
    list field becomes a one-entry list."""
    section, name, index = _locate(config, path)
    if index is not None:
        _read(section, name)[index] = value
    elif isinstance(section, dict):
        section[name] = value
    else:
        if isinstance(getattr(section, name), list) and not isinstance(value, list):
            value = [value]
        setattr(section, name, value)


def config_value(config, path):
    """The value at ``path`` (as ``set_config_value`` names it) in ``config``; None for a new dict key."""
    section, name, index = _locate(config, path)
    current = _read(section, name)
    return current if index is None else current[index]


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
