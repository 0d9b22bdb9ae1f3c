"""A user's joint vector (q, q_guess, held_torque, a log's q) checked before it reaches Drake.

Drake's SetPositions / SetVelocities assert the size and finiteness of what they get and end the
process (no exception) on a wrong-size or NaN vector; every public function that hands a user's vector
to Drake checks it first with ``core.arguments.joint_vector`` (``joint_rows`` for a log), a one-line
ArgumentError naming the callee and the argument. And a path's heading is refused where the path is
built if the path's normal reaches it anywhere along its course, not only at its first point."""

import importlib.metadata
import logging
import math
from pathlib import Path

import numpy as np
import pytest

from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant

from drake_hybrid.analysis.environment import row_forces
from drake_hybrid.analysis.kinematic_instability import analytic_eigenvalues, tip_position, two_link_plant
from drake_hybrid.core.arguments import joint_rows, joint_vector
from drake_hybrid.core.errors import ArgumentError, PathError
from drake_hybrid.core.kinematics import inverse_kinematics
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import check_start, set_initial_conditions, static_torque
from drake_hybrid.station.clearance import robot_penetrations
from drake_hybrid.station.start import holding_torque, prime_start
from drake_hybrid.tasks.builtin.grinding import pad_positions
from drake_hybrid.tasks.builtin.robots import worst_condition_number
from drake_hybrid.tasks.path import build_path, with_path
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.robots import load_arm

logging.getLogger("drake").setLevel(logging.ERROR)

KINOVA = Path(importlib.metadata.distribution("example-robot-data").locate_file(
    "cmeel.prefix/share/example-robot-data")) / "robots/kinova_description/robots/kinova.urdf"

# The classes of a bad joint vector: too short, too long, NaN, inf, a matrix, a number, text, None.
BAD_VECTORS = {"short": lambda n: [0.0] * (n - 1), "long": lambda n: [0.0] * (n + 1),
               "nan": lambda n: [math.nan] * n, "inf": lambda n: [0.0] * (n - 1) + [math.inf],
               "matrix": lambda n: [[0.0] * n] * 2, "number": lambda n: 0.5, "text": lambda n: "home",
               "none": lambda n: None}


@pytest.fixture(scope="module")
def window():
    """The window task's discrete station at its start (3 joints): (scenario, root context, q0)."""
    scenario = build_scenario(get_task("window-washing").default_config(duration=0.1), with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    q0 = scenario.plant.GetPositions(scenario.plant.GetMyContextFromRoot(context), scenario.robot.arm)
    return scenario, context, q0


@pytest.fixture(scope="module")
def kinova(tmp_path_factory):
    return load_arm(KINOVA, flange="j2s6s200_end_effector", cache_dir=tmp_path_factory.mktemp("cache"))


def raises_naming(name, call):
    with pytest.raises(ArgumentError) as error:
        call()
    message = str(error.value)
    assert "\n" not in message and name in message, message
    return message


@pytest.mark.parametrize("kind", ["positions", "velocities", "actuators"])
@pytest.mark.parametrize("bad", sorted(BAD_VECTORS))
def test_joint_vector_refuses_every_class(kind, bad):
    plant, _ = two_link_plant()
    count = {"positions": plant.num_positions, "velocities": plant.num_velocities,
             "actuators": plant.num_actuated_dofs}[kind]()
    assert joint_vector([0.1] * count, "q", "f", plant, kind=kind).shape == (count,)
    message = raises_naming("q", lambda: joint_vector(BAD_VECTORS[bad](count), "q", "f", plant, kind=kind))
    assert message.startswith("f: q must be a vector of 2 finite numbers")


def test_joint_vector_counts_a_model_instance_and_joint_rows_a_log():
    plant, _ = two_link_plant()
    arm = plant.GetModelInstanceByName("planar_2r")
    assert joint_vector([0.1, 0.2], "q", "f", plant, arm).tolist() == [0.1, 0.2]
    empty = MultibodyPlant(0.0)
    empty.Finalize()
    assert raises_naming("q", lambda: joint_vector([0.1, 0.2], "q", "f", empty)).startswith(
        "f: q must be a vector of 0 finite numbers")
    assert joint_rows([[0.0, 0.1]] * 3, "log['q']", "f", plant).shape == (3, 2)
    for bad in ([0.0, 0.1], [[0.0, 0.1, 0.2]], [[0.0, math.nan]], "q"):
        raises_naming("log['q']", lambda bad=bad: joint_rows(bad, "log['q']", "f", plant))


@pytest.mark.parametrize("bad", sorted(BAD_VECTORS))
def test_start_functions_refuse_a_bad_q(window, bad):
    scenario, context, _ = window
    q = BAD_VECTORS[bad](3)
    assert raises_naming("q", lambda: holding_torque(scenario, q, [10.0])).startswith("holding_torque: q")
    assert raises_naming("q", lambda: static_torque(scenario, q)).startswith("static_torque: q")
    assert raises_naming("q", lambda: check_start(scenario, q)).startswith("check_start: q")
    assert raises_naming("q", lambda: robot_penetrations(scenario.diagram, context, scenario, q)).startswith(
        "robot_penetrations: q")
    if q is not None:                      # row_forces: None keeps the context's own q, v
        assert raises_naming("q", lambda: row_forces(scenario, context, q=q)).startswith("row_forces: q")
        assert raises_naming("v", lambda: row_forces(scenario, context, v=q)).startswith("row_forces: v")


@pytest.mark.parametrize("bad", ["short", "nan", "text"])
def test_prime_start_and_holding_torque_refuse_their_other_arguments(window, bad):
    scenario, context, q0 = window
    assert scenario.controller.control_period is not None          # a sampled controller: it holds a torque
    torque = holding_torque(scenario, q0, [10.0])
    held = BAD_VECTORS[bad](len(torque))
    assert raises_naming("held_torque", lambda: prime_start(scenario, context, held)).startswith(
        "prime_start: held_torque")
    assert raises_naming("integrals", lambda: prime_start(scenario, context, torque, integrals=held)).startswith(
        "prime_start: integrals")
    assert raises_naming("desired_force", lambda: holding_torque(scenario, q0, BAD_VECTORS[bad](1))).startswith(
        "holding_torque: desired_force")


def test_systems_and_root_context_are_named(window):
    scenario, context, q0 = window
    raises_naming("systems", lambda: holding_torque(None, q0, [10.0]))
    raises_naming("systems", lambda: prime_start(None, context, np.zeros(3)))
    plant_context = scenario.plant.GetMyMutableContextFromRoot(context)
    raises_naming("root_context", lambda: prime_start(scenario, plant_context, np.zeros(3)))


@pytest.mark.parametrize("bad", sorted(BAD_VECTORS))
def test_loaded_arm_refuses_a_bad_q(kinova, bad):
    q = BAD_VECTORS[bad](kinova.num_joints)
    for method in ("pad_pose", "pad_jacobian", "condition_number"):
        assert raises_naming("q", lambda: getattr(kinova, method)(q)).startswith(f"LoadedArm.{method}: q")
    if q is not None:                      # find_joint_guess: near=None is no seed near anything
        raises_naming("near", lambda: kinova.find_joint_guess(RigidTransform([0.4, 0.0, 0.3]), near=q))


@pytest.mark.parametrize("length_scale", [-1.0, 0.0, math.nan, "x"])
def test_condition_number_refuses_a_bad_length_scale(kinova, length_scale):
    q = [0.1, 3.6, 1.2, 0.0, 1.5, 0.0]
    assert kinova.condition_number(q) > 1
    raises_naming("length_scale", lambda: kinova.condition_number(q, length_scale=length_scale))


@pytest.mark.parametrize("bad", sorted(BAD_VECTORS))
def test_inverse_kinematics_refuses_a_bad_guess(window, bad):
    scenario, _, q0 = window
    kinematics = scenario.controller.kinematics
    context = kinematics.plant.CreateDefaultContext()
    target = RigidTransform([0.4, 0.0, 0.3])
    raises_naming("q_guess", lambda: inverse_kinematics(kinematics, context, target, BAD_VECTORS[bad](3)))


def test_inverse_kinematics_refuses_its_other_arguments(window):
    scenario, context, q0 = window
    kinematics = scenario.controller.kinematics
    plant_context = kinematics.plant.CreateDefaultContext()
    target = RigidTransform([0.4, 0.0, 0.3])
    raises_naming("X_target", lambda: inverse_kinematics(kinematics, plant_context, [0.4, 0.0, 0.3], q0))
    raises_naming("kinematics", lambda: inverse_kinematics(None, plant_context, target, q0))
    raises_naming("plant_context", lambda: inverse_kinematics(kinematics, context, target, q0))
    raises_naming("tolerance", lambda: inverse_kinematics(kinematics, plant_context, target, q0, tolerance=-1))
    raises_naming("max_iterations", lambda: inverse_kinematics(kinematics, plant_context, target, q0,
                                                               max_iterations=0.5))


@pytest.mark.parametrize("bad", ["short", "nan", "text"])
def test_analysis_and_log_helpers_refuse_bad_joint_vectors(window, bad):
    scenario, _, q0 = window
    plant, _ = two_link_plant()
    raises_naming("q", lambda: tip_position(plant, BAD_VECTORS[bad](2)))
    raises_naming("q0", lambda: analytic_eigenvalues("raibert-craig", q0=BAD_VECTORS[bad](2)))
    rows = [BAD_VECTORS[bad](3)] if bad != "text" else "q"
    raises_naming("log['q']", lambda: pad_positions(scenario, {"q": rows}))
    raises_naming("positions", lambda: worst_condition_number(scenario.controller.kinematics,
                                                              scenario.controller_plant, rows))
    assert pad_positions(scenario, {"q": [q0, q0]}).shape == (2,)


def test_a_heading_along_the_path_normal_later_on_is_refused_where_the_path_is_built():
    """surface-polishing's raster over the sphere: a heading equal to the path's normal 1.2 s in."""
    task = get_task("surface-polishing")
    config = task.default_config()
    path = build_path(task, config)
    normal = path.evaluate(1.2).normal
    assert np.degrees(np.arccos(normal @ path.evaluate(0.0).normal)) > 10    # usable at the first point
    with pytest.raises(PathError) as error:
        build_path(task, with_path(config, heading=[float(x) for x in normal]))
    message = str(error.value)
    assert "\n" not in message and "path.heading" in message and "path time 1.2 s" in message, message
    tangent = path.evaluate(1.2).velocity
    build_path(task, with_path(config, heading=[float(x) for x in tangent / np.linalg.norm(tangent)]))
