"""Bad input through the Python API, generated: what a Drake user composing their own diagram passes.

Every argument of the public constructors (``HybridController``, ``HybridGains``, the sources, the
supervisor, the sensors and filters, ``CustomTask``) is given a value of every bad class its kind has:
a string where a number belongs, None, a bool, NaN, inf, a value out of range, a matrix where a vector
is meant, a vector of the wrong size, a mapping, a callable that is not one. Each must end in one line
of the ``DrakeHybridError`` family that names the argument (never an AttributeError, a numpy error or
a silent acceptance). The generator walks the table below, so an argument added to it is fuzzed in
every class; Hypothesis then draws values nobody listed, and a value is accepted only if its kind
allows it.
"""

import functools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pydrake.math import RigidTransform

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode, HybridGains, gain_matrix
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.safety import SafetyConfig
from drake_hybrid.control.supervision import ContactSupervisor, SupervisionConfig
from drake_hybrid.core.errors import DrakeHybridError
from drake_hybrid.systems.low_pass_filter import LowPassFilter
from drake_hybrid.systems.sources import Profile, ProfileSource
from drake_hybrid.systems.wrench_conditioner import WrenchConditioner
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.plant import build_controller_plant
from drake_hybrid.tasks.registry import get_task

# -- the bad values of each kind of argument ----------------------------------------------------------

NOT_A_NUMBER = [("a numeric string", "0.001"), ("a word", "x"), ("None", None), ("a bool", True),
                ("a list", [1.0]), ("a mapping", {"a": 1.0}), ("NaN", math.nan)]
BAD = {
    # a period (s): positive, finite; None allowed (continuous)
    "period": NOT_A_NUMBER[:2] + NOT_A_NUMBER[3:] + [("inf", math.inf), ("zero", 0.0), ("negative", -1e-3)],
    "period, required": NOT_A_NUMBER + [("inf", math.inf), ("zero", 0.0), ("negative", -1e-3)],
    "positive": NOT_A_NUMBER + [("inf", math.inf), ("zero", 0.0), ("negative", -1.0)],
    "nonnegative": NOT_A_NUMBER + [("inf", math.inf), ("negative", -1.0)],
    "point": [("NaN entry", [math.nan, 0.0, 0.0]), ("inf entry", [0.0, math.inf, 0.0]), ("2 entries", [0.0, 0.0]),
              ("a matrix", np.eye(3)), ("a word", "tip"), ("None", None), ("a word entry", [0.0, 0.0, "x"]),
              ("a number", 0.1), ("a mapping", {"x": 0.0})],
    "bool": [("a word", "yes"), ("an int", 1), ("None", None), ("a list", [True])],
    "callable": [("None", None), ("a number", 5), ("a word", "add_robot")],
    "gains": [("a mapping", {"velocity": [10.0]}), ("a word", "fast"), ("a number", 5.0), ("a list", [10.0])],
    "mode": [("an unknown word", "force"), ("None", None), ("a number", 3)],
    "gain": [("None", None), ("a word", "x"), ("a mapping", {"a": 1.0}), ("a NaN", [math.nan]), ("an inf", [math.inf]),
             ("ragged", [[1.0, 2.0], [3.0]]), ("a word entry", [1.0, "x"]), ("tiny", [1e-300]), ("huge", [1e300]),
             ("negative", [-1.0]), ("a 3x3 matrix for 2 rows", np.eye(3)), ("a bool", True)],
    "gain, may be 0": [],
    "gain scalar": NOT_A_NUMBER + [("inf", math.inf), ("negative", -1.0), ("huge", 1e300)],
    "profile": [("a mapping", {"kind": "constant"}), ("a word", "constant"), ("None", None)],
    "profile values": [("NaN entry", [math.nan, 0.0]), ("wrong size", [0.1]), ("a word", "x"), ("None", None),
                       ("a matrix", np.eye(2))],
    "size": [("a word", "2"), ("a fraction", 2.5), ("negative", -1), ("None", None), ("a bool", True),
             ("huge", 2**40)],
    "plant": [("a word", "ur5e"), ("None", None), ("a number", 3)],
    "space": [("a word", "window"), ("None", None), ("a mapping", {})],
    "frame": [("an unknown name", "no_such_frame"), ("a number", 5), ("None", None)],
    "config": [("a mapping", {"approach_speed": 0.02}), ("None", None), ("a word", "supervision")],
    "config or None": [("a mapping", {"approach_speed": 0.02}), ("a word", "supervision"), ("a number", 1.0)],
    "pose": [("a matrix", np.eye(4)), ("a list", [0.0, 0.0, 0.0]), ("None", None)],
    "matrix 2x2": [("3x3", np.eye(3)), ("NaN", [[math.nan, 0.0], [0.0, 1.0]]), ("a word", "x"), ("a vector", [1.0, 2.0])],
    "rows": [("out of range", [5]), ("a fraction", [0.5]), ("a word", ["x"]), ("a number", 1.5)],
    "phase": [("an unknown number", 7), ("a word", "CONTACT"), ("None", None)],
    "text": [("None", None), ("a number", 5), ("a list", ["a"])],
}


# -- the callees: valid arguments, and the kind of each ------------------------------------------------

@functools.lru_cache(maxsize=None)
def window():
    task = get_task("window-washing")
    config = task.default_config()
    plant, robot = build_controller_plant(task, config)
    return plant, robot, task.constraint_space(config)


def controller(**changes):
    plant, robot, space = window()
    arguments = dict(plant=plant, end_effector_frame=robot.end_effector_frame,
                     end_effector_point=robot.end_effector_point, constraint_space=space, fast_law=False)
    arguments.update(changes)
    return HybridController(**arguments)


def sampled_controller(**changes):
    return controller(**dict(dict(control_period=1e-3), **changes))


def gains(**changes):
    return HybridGains(**changes).matrices(2, 1, "impedance-force", control_period=1e-3)


def profile_source(**changes):
    arguments = dict(velocity_profile=Profile(value=[0.1, 0.0]), force_profile=Profile(value=[-10.0]),
                     velocity_size=2, force_size=1)
    arguments.update(changes)
    return ProfileSource(**arguments)


def profile(**changes):
    fields = dict(kind="smooth_step", value=[0.1, 0.0], final_value=[0.2, 0.0], duration=1.0)
    fields.update(changes)
    return ProfileSource(Profile(**fields), Profile(value=[-10.0]), 2, 1)


def supervisor(**changes):
    arguments = dict(config=SupervisionConfig(), force_size=1, kinematic_rows=(), period=1e-3,
                     initial_phase=ContactPhase.APPROACH)
    arguments.update(changes)
    return ContactSupervisor(**arguments)


def custom_task(**changes):
    arguments = dict(name="mine", add_robot=lambda plant: None, add_workpiece=lambda plant: [],
                     constraint_space=window()[2], start_pose=RigidTransform(), joint_guess=[0.1, 0.2, 0.3])
    arguments.update(changes)
    return CustomTask(**arguments)


def safety(**changes):
    return controller(safety=SafetyConfig(**changes))


CALLEES = {
    "HybridController": (controller, {
        "plant": "plant", "end_effector_frame": "frame", "end_effector_point": "point", "constraint_space": "space",
        "gains": "gains", "mode": "mode", "control_period": "period", "sample_lead": "bool",
        "plant_time_step": "nonnegative", "wrench_lag": "nonnegative", "compensate_tangential_force": "bool",
        "fast_law": "bool", "velocity_row_inertia": "matrix 2x2", "safety": "config or None"}),
    "HybridController (sampled)": (sampled_controller, {"sampled_diagnostics": "bool", "guarded_move": "config or None"}),
    "HybridGains": (gains, {"velocity": "gain", "position": "gain", "force_integral": "gain",
                            "force_proportional": "gain, may be 0", "impedance_mass": "gain",
                            "null_space_damping": "gain scalar", "constraint_frequency": "gain scalar"}),
    "SafetyConfig": (safety, {"max_joint_acceleration": "positive", "singularity_threshold": "nonnegative",
                              "anti_windup": "bool", "effort_limits": "profile values"}),
    "ProfileSource": (profile_source, {"velocity_profile": "profile", "force_profile": "profile",
                                       "velocity_size": "size", "force_size": "size"}),
    "Profile": (profile, {"value": "profile values", "final_value": "profile values", "duration": "positive",
                          "start_time": "profile start"}),
    "ContactSupervisor": (supervisor, {"config": "config", "force_size": "size", "period": "period, required",
                                       "kinematic_rows": "rows", "initial_phase": "phase"}),
    "CustomTask": (custom_task, {"name": "text", "add_robot": "callable", "add_workpiece": "callable",
                                 "constraint_space": "space", "start_pose": "pose", "joint_guess": "point guess",
                                 "description": "text"}),
    "LowPassFilter": (lambda **changes: LowPassFilter(**dict(dict(size=6, bandwidth_hz=50.0, period=None), **changes)),
                      {"size": "size", "bandwidth_hz": "positive", "period": "period"}),
    "WrenchConditioner": (lambda **changes: WrenchConditioner(**dict(dict(period=1e-3), **changes)),
                          {"period": "period, required", "bandwidth_hz": "nonnegative", "max_hold_time": "nonnegative"}),
}
BAD["profile start"] = NOT_A_NUMBER + [("inf", math.inf)]
BAD["gain, may be 0"] = [entry for entry in BAD["gain"] if entry[0] != "tiny"]
BAD["point guess"] = [entry for entry in BAD["point"] if entry[0] not in ("2 entries", "a number")]


def cases():
    for callee, (call, arguments) in CALLEES.items():
        for argument, kind in arguments.items():
            for label, value in BAD[kind]:
                yield pytest.param(callee, argument, value, id=f"{callee}.{argument}={label}")


def _check_refusal(error, argument):
    message = str(error)
    assert isinstance(error, DrakeHybridError), f"{type(error).__name__}: {message}"
    assert "\n" not in message.strip(), f"more than one line: {message!r}"
    assert argument in message, f"the message does not name '{argument}': {message}"


@pytest.mark.parametrize("callee, argument, value", list(cases()))
def test_a_bad_argument_is_one_typed_line_naming_it(callee, argument, value):
    call, _ = CALLEES[callee]
    try:
        call(**{argument: value})
    except Exception as error:   # noqa: BLE001 -- the type is what is checked
        _check_refusal(error, argument)
    else:
        pytest.fail(f"{callee}({argument}={value!r}) was accepted")


def test_the_generator_covers_every_class():
    assert len(list(cases())) >= 250
    kinds = {kind for _, arguments in CALLEES.values() for kind in arguments.values()}
    assert kinds == set(BAD), set(BAD) ^ kinds


@pytest.mark.parametrize("callee", sorted(CALLEES))
def test_the_valid_arguments_are_accepted(callee):
    """The table's valid arguments build (so a refusal above is the bad value's, not the base's)."""
    CALLEES[callee][0]()


# -- the cases of issue 32, each by name --------------------------------------------------------------

@pytest.mark.parametrize("call, error, match", [
    (lambda: controller(control_period=math.inf), "ArgumentError", r"control_period must be a finite number > 0"),
    (lambda: controller(control_period="0.001"), "ArgumentError", r"control_period .* got '0.001' \(a str\)"),
    (lambda: controller(end_effector_point=[math.nan, 0, 0]), "ArgumentError", r"end_effector_point .* got \[nan, 0, 0\]"),
    (lambda: controller(gains=HybridGains(velocity=[1e-300, 1e-300])), "GainError",
     r"velocity \(K_v\) designs a loop that decays at 1e-300 1/s \(a time constant of 1e\+300 s\)"),
    (lambda: controller(gains=HybridGains(velocity=[1e300, 1e300])), "GainError",
     r"velocity \(K_v\) designs a loop of rate 1e\+300 1/s, faster than 1e\+06 1/s"),
    (lambda: gains(velocity=[1e-300, 1e-300]), "GainError",
     r"velocity \(K_v\) and position \(K_p\) designs a loop that decays at 5e-301 1/s"),
    (lambda: gains(velocity=np.eye(3)), "GainError", r"velocity \(K_v\) is a 3x3 matrix; for 2 rows it must be"),
    (lambda: gains(velocity=None), "GainError", r"velocity must be a number, a vector or a matrix .* got None"),
    (lambda: gains(null_space_damping="x"), "GainError", r"null_space_damping must be .* got 'x' \(a str\)"),
    (lambda: controller(gains={"velocity": [10.0]}), "ArgumentError", r"gains must be a HybridGains .* got a dict"),
    (lambda: custom_task(add_robot=None), "ArgumentError", r"add_robot must be a callable add_robot\(plant\)"),
    (lambda: custom_task(joint_guess=["x", 0.1, 0.2]), "ArgumentError", r"joint_guess must be a vector"),
    (lambda: gain_matrix([1.0], -1, "velocity"), "GainError", r"size must be a finite integer >= 0, got -1"),
    (lambda: controller(gains=HybridGains(velocity=[5.0]), control_period=0.5), "GainError",
     r"velocity \(K_v\) designs a loop of rate 5 1/s, faster than 2 1/s \(the sampling rate 1/h of this "
     r"controller's control_period h = 0.5 s"),
    (lambda: ControlMode.parse("sideways"), "ArgumentError", r"unknown control mode 'sideways'"),
    (lambda: gains(force_damping=-1.0), "GainError", r"force_damping \(K_fd\) must be positive semidefinite"),
    (lambda: controller(gains=HybridGains(velocity=[5.0, 5.0], force_damping=[2000.0]), control_period=1e-3),
     "GainError", r"force_damping \(K_fd\) has an eigenvalue of 2e\+03 1/s, faster than 1000 1/s"),
])
def test_the_cases_of_the_issue(call, error, match):
    with pytest.raises(DrakeHybridError, match=match) as raised:
        call()
    assert type(raised.value).__name__ == error and "\n" not in str(raised.value)


def test_a_gain_matrix_for_no_rows_is_empty():
    assert gain_matrix([1.0], 0, "velocity").shape == (0, 0)


# -- values nobody listed (Hypothesis): a typed refusal naming the argument, or a value its kind allows --

ANYTHING = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
    st.lists(st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=3), max_size=3),
    st.dictionaries(st.text(max_size=3), st.floats(), max_size=2), st.just(np.eye(3)), st.just(object()))


def _finite_number(value):
    return (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value))


# (callee, argument, whether a value is allowed): accepted exactly when allowed.
PREDICATES = [
    ("HybridController", "control_period", lambda v: v is None or (_finite_number(v) and 0 < v < 1 / 30)),
    # (1/30 s: the default gains' fastest loop is the kinematic rows' 2 w_c = 30 1/s, which a sampled
    # controller must tick faster than)
    ("HybridController", "wrench_lag", lambda v: _finite_number(v) and v >= 0),
    ("HybridController", "plant_time_step", lambda v: _finite_number(v) and v >= 0),
    ("HybridController", "end_effector_point", lambda v: isinstance(v, list) and len(v) == 3
     and all(_finite_number(x) for x in v)),
    ("HybridController", "sample_lead", lambda v: isinstance(v, bool)),
    ("ContactSupervisor", "period", lambda v: _finite_number(v) and v > 0),
    ("ContactSupervisor", "force_size", lambda v: _finite_number(v) and float(v).is_integer() and 1 <= v <= 6),
    ("LowPassFilter", "bandwidth_hz", lambda v: _finite_number(v) and v > 0),
]


@pytest.mark.parametrize("callee, argument, allowed", PREDICATES, ids=[f"{c}.{a}" for c, a, _ in PREDICATES])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=ANYTHING)
def test_random_values_are_refused_or_allowed(callee, argument, allowed, value):
    call, _ = CALLEES[callee]
    try:
        call(**{argument: value})
    except Exception as error:   # noqa: BLE001 -- the type is what is checked
        _check_refusal(error, argument)
        assert not allowed(value), f"{callee}({argument}={value!r}) refused: {error}"
    else:
        assert allowed(value), f"{callee}({argument}={value!r}) was accepted"
