"""A ScenarioConfig built or changed in Python is checked as a YAML file is: the same per-field type
rules (core.schema.type_mismatch), run by ``ScenarioConfig.validate`` (so by prepare_config,
build_scenario and simulate) and by ``replace``, ``with_path`` and ``Task.default_config``; one
typed line naming the field, never a raw AttributeError / TypeError or a truthy string taken as true."""

import dataclasses

import numpy as np
import pytest

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.errors import ArgumentError, ConfigError, DrakeHybridError, PathError
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.scenario.builder import build_scenario, prepare_config
from drake_hybrid.station.contact import ContactConfig
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import StartConfig, load_config
from drake_hybrid.tasks.path import with_path
from drake_hybrid.tasks.registry import get_task


@pytest.fixture(scope="module")
def base():
    return get_task("window-washing").default_config(duration=0.1)


def changed(config, dotted, value):
    """A deep copy of ``config`` with the field ``dotted`` ("supervision.enabled") set to ``value``
    (as a user does: the attribute assigned after construction, bypassing any constructor)."""
    copy = dataclasses.replace(config)
    *path, last = dotted.split(".")
    owner = copy
    for part in path:
        section = dataclasses.replace(getattr(owner, part))
        setattr(owner, part, section)
        owner = section
    setattr(owner, last, value)
    return copy


# (dotted field, bad value, the same value in YAML or None where YAML has no such value)
WRONG_TYPES = [
    ("duration", True, "true"),                      # a bool is not a number
    ("duration", "abc", "abc"),                      # a word is not a number
    ("duration", [0.1], "[0.1]"),
    ("control_period", "0.001", None),               # Python: a string is refused, not parsed
    ("max_duration", None, None),
    ("mode", 3, "3"),
    ("task", 5, "5"),
    ("compensate_tangential_force", "yes", "'yes'"),  # a truthy string is not true
    ("compensate_tangential_force", 0, "0"),          # nor is a number
    ("task_parameters", [1.0], "[1.0]"),
    ("task_parameters", {"window_height": "x"}, "{window_height: x}"),
    ("task_options", {"joints": 3}, None),
    ("supervision.enabled", "false", "'false'"),
    ("start.in_contact", "no", "'no'"),
    ("start.configuration", "0.1", "'0.1'"),
    ("start.configuration", [0.1, "x"], "[0.1, x]"),
    ("contact.friction", "x", "x"),
    ("contact.pad_modulus", True, "true"),
    ("sensor.bandwidth_hz", True, "true"),
    ("sensor.bandwidth_hz", "x", "x"),
    ("sensor.condition", "yes", "'yes'"),
    ("safety.anti_windup", "no", "'no'"),
    ("safety.effort_limits", 10.0, "10.0"),
    ("path.speed", True, "true"),
    ("path.speed", "x", "x"),
    ("path.lift_off", "no", "'no'"),
    ("path.heading", "x", "x"),
    ("gains.null_space_damping", "10", None),
    ("gains.velocity", [True], "[true]"),
    ("desired_force.value", ["-10"], None),
    ("model_error.joint_damping", False, "false"),
    ("mechanism.source", 1, "1"),
]


def _ids(case):
    return f"{case[0]}={case[1]!r}"


@pytest.mark.parametrize("dotted, bad, _", WRONG_TYPES, ids=map(_ids, WRONG_TYPES))
def test_a_wrong_type_set_in_python_is_refused_naming_the_field(base, dotted, bad, _):
    config = changed(base, dotted, bad)
    for check in (config.validate, lambda: prepare_config(config)):
        with pytest.raises(ConfigError) as refused:
            check()
        message = str(refused.value)
        assert message.startswith(f"{dotted}") and "expected" in message and "\n" not in message, message


@pytest.mark.parametrize("dotted, bad, yaml_value", [case for case in WRONG_TYPES if case[2] is not None],
                         ids=[_ids(case) for case in WRONG_TYPES if case[2] is not None])
def test_python_and_yaml_refuse_a_wrong_type_with_the_same_message(base, dotted, bad, yaml_value):
    """One implementation for both paths: the message of the Python config is the YAML loader's."""
    *path, last = dotted.split(".")
    text = "".join(f"{'  ' * depth}{part}:\n" for depth, part in enumerate(path)) + f"{'  ' * len(path)}{last}: {yaml_value}"
    with pytest.raises(ConfigError) as from_yaml:
        load_config(data=text, defaults=base)
    with pytest.raises(ConfigError) as from_python:
        changed(base, dotted, bad).validate()
    assert str(from_python.value) == str(from_yaml.value)


SECTIONS_OF_THE_WRONG_KIND = [
    ("gains", {"velocity": [1.0]}, "HybridGains"),
    ("supervision", {"enabled": True}, "SupervisionConfig"),
    ("path", {}, "PathConfig"),
    ("start", None, "StartConfig"),
    ("contact", [1.0], "ContactConfig"),
    ("plant", {"time_step": 0.0}, "MultibodyPlantConfig"),
    ("desired_force", [-10.0], "Profile"),
    ("desired_velocity", "0.1", "Profile"),
    ("sensor", {"bandwidth_hz": 10.0}, "ContactSensorConfig or a WristSensorConfig"),
    ("sensor", "vision", "ContactSensorConfig or a WristSensorConfig"),
    ("path.pattern", {"kind": "raster"}, "PatternConfig"),
    ("path.waypoints", [[0.4, 0.0, 0.25]], "WaypointConfig"),
]


@pytest.mark.parametrize("dotted, bad, kind", SECTIONS_OF_THE_WRONG_KIND,
                         ids=[_ids(case) for case in SECTIONS_OF_THE_WRONG_KIND])
def test_a_section_that_is_not_its_dataclass_is_refused_naming_the_class(base, dotted, bad, kind):
    with pytest.raises(ConfigError, match=rf"^{dotted}(\[0\])?: expected a {kind}, got .*; build the section with"):
        prepare_config(changed(base, dotted, bad))


def test_numpy_numbers_tuples_and_arrays_are_python_forms_of_the_yaml_types(base):
    config = dataclasses.replace(base, duration=np.float64(0.1), log_period=np.float32(1e-3),
                                 start=dataclasses.replace(base.start, configuration=np.array(base.start.configuration),
                                                           in_contact=np.bool_(True)),
                                 task_parameters={"window_height": np.float64(0.3)} if "window_height" in
                                 base.task_parameters else dict(base.task_parameters))
    config.path.heading = (1.0, 0.0, 0.0)
    assert prepare_config(config).config.duration == pytest.approx(0.1)


@pytest.mark.parametrize("call, name", [
    (lambda config: config.replace(duraton=1.0), "duraton"),
    (lambda config: with_path(config, spede=0.1), "spede"),
    (lambda config: get_task("window-washing").default_config(duraton=1.0), "duraton"),
])
def test_an_unknown_keyword_is_refused_as_the_yaml_loader_refuses_an_unknown_key(base, call, name):
    with pytest.raises(ConfigError, match=rf"unknown field '{name}'; its fields are .*\bspeed\b|unknown field "
                                          rf"'{name}'; its fields are .*\bduration\b"):
        call(base)


@pytest.mark.parametrize("call, field", [
    (lambda config: config.replace(duration=True), "duration"),
    (lambda config: config.replace(gains={"velocity": [1.0]}), "gains"),
    (lambda config: with_path(config, speed="0.05"), "path.speed"),
    (lambda config: with_path(config, lift_off="no"), "path.lift_off"),
    (lambda config: get_task("window-washing").default_config(duration="abc"), "duration"),
    (lambda config: get_task("window-washing").default_config(desired_force=["x"]), "desired_force.value[0]"),
    (lambda config: get_task("window-washing").default_config(desired_force=5), "desired_force"),
    (lambda config: get_task("window-washing").default_config(duration=-1.0), "duration"),
    (lambda config: get_task("window-washing").default_config(options=["x"]), "options"),
])
def test_replace_with_path_and_default_config_check_what_they_change(base, call, field):
    with pytest.raises(ConfigError) as refused:
        call(base)
    assert field in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.parametrize("call", [simulate, build_scenario, prepare_config], ids=lambda call: call.__name__)
@pytest.mark.parametrize("bad", [{"task": "window-washing"}, "window-washing", None, HybridGains()],
                         ids=["dict", "str", "None", "a section"])
def test_a_run_of_something_that_is_not_a_scenario_config_is_refused_at_the_call(call, bad):
    with pytest.raises(ArgumentError, match=r": config must be a ScenarioConfig .*, got "):
        call(bad)


def test_load_config_refuses_data_that_is_not_text():
    with pytest.raises(ConfigError, match="load_config: data must be a YAML text"):
        load_config(data={"duration": 1.0})


@pytest.mark.parametrize("name", ["no-such-task", 5, None])
def test_an_unknown_task_is_a_package_error_naming_the_known_tasks(base, name):
    with pytest.raises(ArgumentError, match="get_task: "):
        get_task(name)
    if isinstance(name, str):
        with pytest.raises(ArgumentError, match="available tasks: .*window-washing"):
            get_task(name)
        with pytest.raises(ConfigError, match=r"^task: unknown task 'no-such-task'; available tasks: .*window-washing"):
            prepare_config(base.replace(task=name))


@pytest.mark.parametrize("heading", [[float("nan"), 0.0, 0.0], [float("inf"), 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0]])
def test_path_heading_must_be_a_finite_non_zero_direction(base, heading):
    config = with_path(base, heading=heading)
    with pytest.raises(DrakeHybridError, match=r"path\.heading(\[0\])? must be"):
        config.validate()
    with pytest.raises(PathError, match=r"^path\.heading must be a world direction \[x, y, z\] \(finite, not zero\)"):
        config.path.validate()


def test_the_checks_leave_a_valid_python_config_as_it_is(base):
    config = base.replace(supervision=SupervisionConfig(enabled=True), contact=ContactConfig(friction=0.2),
                          start=dataclasses.replace(base.start), desired_velocity=Profile(value=[0.05, 0.0]))
    assert config.validate() is config and config.supervised and config.contact.friction == 0.2
    assert isinstance(StartConfig().in_contact, bool)
