"""Bad input, generated: every config field, every command-line flag, every sweep-spec key.

Each case must end in a typed, one-line error that names the offending field, flag or key. The
generator walks the
ScenarioConfig of every task, so a field added later is fuzzed too. Each case is bounded in time:
configs are checked the way ``build_scenario`` checks them (``config.validate()`` and
``task.options(config)``) without building the plant.
"""

import dataclasses
import math

import pytest
import yaml

from drake_hybrid.cli import main
from drake_hybrid.core.errors import DrakeHybridError, ForceSignError
from drake_hybrid.experiments.sweep import sweep_points
from drake_hybrid.experiments.sweep_spec import SweepSpecError, load_spec
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.tasks.config import ALLOWED_INFINITE, load_config
from drake_hybrid.tasks.registry import TASKS, get_task

TASK = "window-washing"

def _leaves(value, prefix=""):
    """(dotted path, value) of every leaf field of a config dataclass (Drake structs through __fields__)."""
    if dataclasses.is_dataclass(value):
        names = [f.name for f in dataclasses.fields(value)]
    elif hasattr(value, "__fields__"):
        names = [f.name for f in value.__fields__]
    else:
        yield prefix, value
        return
    for name in names:
        yield from _leaves(getattr(value, name), f"{prefix}.{name}" if prefix else name)


def _yaml_at(path, text):
    """The YAML mapping that sets dotted ``path`` to the YAML scalar/flow ``text``."""
    for segment in reversed(path.split(".")):
        text = f"{{{segment}: {text}}}"
    return text[1:-1]


def _bad_values(path, value):
    """(label, YAML text) of bad values for a field holding ``value``."""
    if isinstance(value, bool):
        return [("word", "maybe"), ("list", "[true]")]
    if isinstance(value, float):
        cases = [("nan", ".nan"), ("text", "abc"), ("list", "[1.0, 2.0]"), ("mapping", "{a: 1}")]
        if path not in ALLOWED_INFINITE:
            cases.append(("inf", ".inf"))
        return cases
    if isinstance(value, int):
        return [("fraction", "2.5"), ("text", "abc"), ("nan", ".nan")]
    if isinstance(value, str):
        return [("unknown word", "no-such-value-xyz"), ("list", "[a, b]")]
    if isinstance(value, list):
        return [("nan entry", "[.nan]"), ("text entry", "[abc]"), ("scalar-mapping", "{a: 1}")]
    if isinstance(value, dict):
        return [("not a mapping", "[1, 2]")]
    return []


def config_cases():
    """(task, path, YAML) for every leaf field of every task's config (each field once, from the first
    task that has it), plus an unknown key in every section."""
    cases, seen = [], set()
    for name in sorted(TASKS):
        config = get_task(name).default_config()
        for path, value in _leaves(config):
            if path == "task" or path in seen:
                continue
            seen.add(path)
            for label, text in _bad_values(path, value):
                cases.append(pytest.param(name, path, text, id=f"{path}={label}"))
    for section in sorted({path.split(".")[0] for path in seen if "." in path}):
        cases.append(pytest.param(TASK, f"{section}.no_such_field", "1.0", id=f"{section}.unknown-key"))
    cases.append(pytest.param(TASK, "no_such_section", "1.0", id="unknown-top-level-key"))
    return cases


def _check_one_line(error, *names):
    message = str(error)
    assert "\n" not in message.strip(), f"more than one line: {message!r}"
    assert isinstance(error, ValueError), f"{type(error).__name__} is not a ValueError: {message}"
    assert any(name in message for name in names), f"the message does not name {names}: {message}"


@pytest.mark.parametrize("task_name, path, text", config_cases())
def test_a_bad_config_field_is_one_line_naming_it(task_name, path, text):
    task = get_task(task_name)
    data = f"task: {task_name}\n" + _yaml_at(path, text)
    leaf = path.split(".")[-1]
    with pytest.raises(ValueError) as raised:
        config = load_config(data=data, defaults=task.default_config())
        config.validate()
        task.options(config)
    _check_one_line(raised.value, leaf, path)


def test_the_generator_is_large():
    assert len(config_cases()) >= 250


# -- relations between fields ---------------------------------------------------------------------

RELATIONS = [
    ("control_period: 5.0", "control_period"),
    ("log_period: 5.0", "log_period"),
    ("plant: {time_step: 0.01}\ncontrol_period: 0.001", "plant.time_step"),
    ("start: {in_contact: false}\nsupervision: {approach_speed: 0.0}", "approach_speed"),
    ("duration: 1.0\nduration: 2.0", "duration"),
    ("gains: 5", "5"),
    ("sensor: !NoSuchSensor {}", "NoSuchSensor"),
    ("mode: sideways", "sideways"),
    ("duration: 1.0e9", "max_duration"),
    ("start: {in_contact: false, gap: 1.0}", "start.gap"),
]


@pytest.mark.parametrize("text, name", RELATIONS)
def test_relations_between_fields_are_checked(text, name):
    task = get_task(TASK)
    with pytest.raises(ValueError) as raised:
        config = load_config(data=f"task: {TASK}\n{text}", defaults=task.default_config())
        config.validate()
        task.options(config)
    _check_one_line(raised.value, name)


def test_a_pulling_force_is_a_typed_error_naming_the_sign_convention():
    config = get_task(TASK).default_config()
    config.desired_force.value = [10.0]                 # F is the force ON the robot: +10 pulls
    scenario = build_scenario(config, with_loggers=False)
    with pytest.raises(ForceSignError) as raised:
        set_initial_conditions(scenario, scenario.diagram.CreateDefaultContext())
    _check_one_line(raised.value, "flip the sign of desired_force")


# -- command line -----------------------------------------------------------------------------------

CLI_CASES = [
    (["simulate", TASK, "--duration", value], "--duration") for value in ("0", "-1", "inf", "nan", "1e400")
] + [
    (["simulate", TASK, "--option", option], "option") for option in ("joints", "=", "no_such=1", "chart=euler",
                                                                    "joints=abc", "window_height=abc")
] + [
    (["simulate", TASK, "--config", path], path) for path in ("/no/such/file.yaml", "/")
] + [
    (["simulate", TASK, flag, value], flag) for flag in ("--html",) for value in ("/no/such/dir/a.html", "/")
] + [
    (["analyze", TASK, flag, value], flag) for flag in ("--json", "--plot") for value in ("/no/such/dir/a", "/")
] + [
    (["sweep", TASK, "--grid", value], value) for value in ("/no/such/spec.yaml",)
] + [
    (["analyze", TASK, "--tolerance", value], "--tolerance") for value in ("-1", "nan", "inf", "0", "2")
]


@pytest.mark.parametrize("argv, name", CLI_CASES, ids=[" ".join(argv[1:]) for argv, _ in CLI_CASES])
def test_bad_command_line_input_exits_2_with_one_line(argv, name, capsys):
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and name.strip("-") in error and "Traceback" not in error, error


# -- sweep specs ------------------------------------------------------------------------------------

SPEC_CASES = [
    "parameters: {}",
    "parameters: {duration: [1, 2]}",
    "parameters: {duration: {values: []}}",
    "parameters: {duration: {gaussian: [1, 2]}}",
    "parameters: {duration: {linspace: [1, 2]}}",
    "parameters: {duration: {linspace: [1, 2, 0]}}",
    "parameters: {duration: {linspace: [1, 2, 2.5]}}",
    "parameters: {duration: {logspace: [0, 1, 3]}}",
    "parameters: {duration: {loguniform: [-1, 1]}}",
    "parameters: {duration: {uniform: [2, 1]}}",
    "parameters: {duration: {normal: [1, -1]}}",
    "parameters: {duration: {uniform: [a, 1]}}",
    "parameters: {duration: {values: [1], uniform: [1, 2]}}",
    "parameters: {duration: {values: [1]}}\nsamples: 0",
    "parameters: {duration: {values: [1]}}\nsamples: 2.5",
    "parameters: {duration: {values: [1]}}\nsamples: 3",
    "parameters: {duration: {values: [1]}}\nseed: -1",
    "parameters: {duration: {values: [1]}}\nseed: abc",
    "parameters: {duration: {values: [1]}}\nlinearize: {continuous: maybe}",
    "parameters: {duration: {values: [1]}}\nlinearize: {sampled: true}",
    "parameters: {duration: {values: [1]}}\nstability: {steady_window: 0}",
    "parameters: {duration: {values: [1]}}\nstability: {steady_window: 2}",
    "parameters: {duration: {values: [1]}}\nstability: {steady_tolerance: 0}",
    "parameters: {duration: {values: [1]}}\nstability: {steady_tolerance: .nan}",
    "parameters: {duration: {values: [1]}}\nstability: {margin: 1}",
    "parameters: {duration: {values: [1]}}\nmap: {x: control_period}",
    "parameters: {duration: {values: [1]}}\nmap: {z: duration}",
    "parameters: {duration: {values: [1]}}\ngrid: 3",
    "parameters: {duration: {values: [1]}}\nbase: {duration: 2}",
    "parameters: {duration: {linspace: [1, 2, 20001]}}",
    "parameters: {duration: {values: [1]}}\nmax_points: abc",
    "parameters:\n  gains.velocity: {values: [1]}\n  gains.velocity[0]: {values: [2]}",
    "parameters: [1, 2]",
    "- a\n- b",
    "parameters: {duration: {values: [1]}",
    "parameters: {duration: {values: [1]}}\nstability: {eigenvalue_margin: .nan}",
    "parameters: {duration: {values: [1]}}\nstability: {eigenvalue_margin: .inf}",
    "parameters: {duration: {values: [1]}}\nstability: {steady_tolerance: .inf}",
    "parameters: {duration: {linspace: [.nan, 2, 3]}}",
    "parameters: {duration: {uniform: [1, .inf]}}",
    "",
    "# only a comment",
    "just a word",
]


@pytest.mark.parametrize("text", SPEC_CASES)
def test_a_bad_sweep_spec_is_one_line(text):
    with pytest.raises(SweepSpecError) as raised:
        load_spec(text=text)
    message = str(raised.value)
    assert "\n" not in message.strip() and len(message) < 400, message


# Files that are not YAML configs, given to the flags that take one: (name, bytes or a folder).
BAD_FILES = [("a-folder", None), ("binary.yaml", bytes(range(256)) * 4), ("empty.yaml", b""),
             ("comments.yaml", b"# nothing but a comment\n"), ("latin-1.yaml", "duration: 2.0 # \u00e9".encode("latin-1")),
             ("a-list.yaml", b"- 1\n- 2\n")]


@pytest.mark.parametrize("flag, command", [("--config", "simulate"), ("--config", "analyze"), ("--grid", "sweep")])
@pytest.mark.parametrize("name, content", BAD_FILES, ids=[name for name, _ in BAD_FILES])
def test_a_bad_file_names_the_flag_and_the_file(tmp_path, capsys, flag, command, name, content):
    path = tmp_path / name
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    assert main([command, TASK, flag, str(path)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "Traceback" not in error, error
    assert flag in error and str(path) in error, error


# Sweep values checked like the config fields they set (against the task's default config).
SPEC_VALUE_CASES = [
    ("parameters: {sensor.condition: {values: [maybe, 2]}}", r"sensor.condition.values\[0\] = 'maybe': .* true or false"),
    ("parameters: {sensor.condition: {values: [true, 2]}}", r"sensor.condition.values\[1\] = 2.0"),
    ("parameters: {contact.pad_modulus: {values: [1.0e6, -5]}}", r"pad_modulus.values\[1\] = -5.0: .*must be positive"),
    ("parameters: {mode: {values: [velocity-force, sideways]}}", r"mode.values\[1\] = 'sideways'"),
    ("parameters: {duration: {uniform: [0.5, 1.0e9]}}", r"duration.uniform\[1\] = 1000000000.0: .*max_duration"),
    ("parameters: {control_period: {choice: [0.001, abc]}}", r"control_period.choice\[1\] = 'abc': .* a number"),
    ("parameters: {gains.velocity: {values: [10, -1]}}", r"gains.velocity.values\[1\]"),
]


@pytest.mark.parametrize("text, match", SPEC_VALUE_CASES)
def test_sweep_values_are_checked_like_config_fields(text, match):
    with pytest.raises(SweepSpecError, match=match) as raised:
        sweep_points(TASK, load_spec(text=text))
    assert "\n" not in str(raised.value)


def test_the_fuzz_suite_has_at_least_300_cases():
    total = (len(config_cases()) + len(RELATIONS) + 1 + len(CLI_CASES) + len(SPEC_CASES) + 3 * len(BAD_FILES)
             + len(SPEC_VALUE_CASES))
    assert total >= 300, total
    print(f"{total} bad inputs")


def test_yaml_helpers_build_the_mapping():
    assert yaml.safe_load(_yaml_at("a.b.c", "1.0")) == {"a": {"b": {"c": 1.0}}}
    assert math.isnan(yaml.safe_load(_yaml_at("a", ".nan"))["a"])
    assert issubclass(DrakeHybridError, ValueError)          # every typed error is a ValueError
