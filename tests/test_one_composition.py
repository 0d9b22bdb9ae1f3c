"""One composition: every closed loop the package builds, and the one a user builds, is connected by the
same function (``station.loop.connect_hybrid_loop``), and the names a user starts with are at the front
door (``drake_hybrid``)."""

import ast
import importlib
import inspect
from pathlib import Path

import numpy as np
import pytest

from pydrake.geometry import Cylinder
from pydrake.lcm import DrakeLcm
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

import drake_hybrid
from drake_hybrid.analysis import kinematic_instability
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.surfaces import CylinderSurface, view_projection
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.station.arm import robot_plant
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.contact_start import solve_path_start
from drake_hybrid.station.loggers import add_loggers, read_log
from drake_hybrid.station.loop import add_hybrid_controller
from drake_hybrid.station.path_config import PathConfig, PatternConfig
from drake_hybrid.station.path_job import path_job
from drake_hybrid.station.sensing import ContactSensorConfig
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.faults import SensorFaultConfig
from drake_hybrid.tasks.registry import get_task

PACKAGE = Path(drake_hybrid.__file__).resolve().parent
# The ports that make a system a hybrid law (HybridController, the baselines): what the loop connects.
LAW_INPUTS, LAW_OUTPUT = ("estimated_state", "measured_wrench"), "actuation"
WIRING = "connect_hybrid_loop"


# -- the front door -----------------------------------------------------------------------------------

def test_the_front_door_exports_each_name_from_its_one_home():
    """Every name of ``drake_hybrid.__all__`` imports, and is defined in the module the front door names (a
    function or class is that module's own, not a re-export)."""
    for name in drake_hybrid.__all__:
        value = getattr(drake_hybrid, name)
        module = drake_hybrid._MODULE_OF[name]
        assert getattr(importlib.import_module(module), name) is value
        if inspect.isclass(value) or inspect.isfunction(value):
            assert value.__module__ == module, f"{name} is defined in {value.__module__}, not {module}"


def test_the_front_door_has_what_a_user_starts_with():
    for name in ("HybridController", "simulate", "add_hybrid_controller", "get_task", "path_job",
                 "solve_contact_start", "linearize_at_contact", "ConstraintSpace", "HybridGains"):
        assert name in drake_hybrid.__all__


# -- every connection of a law's ports is made in one place -----------------------------------------------

def _is_law(system):
    return (all(system.HasInputPort(name) for name in LAW_INPUTS) and system.HasOutputPort(LAW_OUTPUT))


@pytest.fixture
def connections(monkeypatch):
    """Every DiagramBuilder.Connect made while the test builds, with the package function that asked for it
    (the innermost frame in drake_hybrid)."""
    made = []
    original = DiagramBuilder.Connect

    def recording(self, *args):
        if len(args) == 2:
            output_port, input_port = args
            caller = next((frame.function for frame in inspect.stack()[1:]
                           if Path(frame.filename).resolve().is_relative_to(PACKAGE)
                           and frame.function not in ("guarded_connect", "_connect_shared")), None)
            made.append((output_port.get_system(), input_port.get_system(), caller))
        return original(self, *args)

    monkeypatch.setattr(DiagramBuilder, "Connect", recording)
    return made


def _law_connections(made):
    return [(output_system.get_name(), input_system.get_name(), caller) for output_system, input_system, caller in made
            if _is_law(output_system) or _is_law(input_system)]


def _assert_one_wiring(made, at_least):
    laws = _law_connections(made)
    assert len(laws) >= at_least, laws
    elsewhere = [connection for connection in laws if connection[2] != WIRING]
    assert not elsewhere, f"connections of a law's ports made outside {WIRING}: {elsewhere}"


@pytest.mark.parametrize("task, change", [
    ("window-washing", {}),
    ("surface-polishing", {}),                                            # a path job: source, supervisor, lift-off
    ("window-washing", {"controller": "raibert-craig"}),                  # a baseline law
])
def test_the_package_runs_wire_the_loop_in_one_place(connections, task, change):
    config = get_task(task).default_config(**change)
    build_scenario(config)
    _assert_one_wiring(connections, at_least=5)


def test_a_supervised_loop_with_faults_and_a_conditioner_is_wired_in_one_place(connections):
    config = get_task("window-washing").default_config()
    config.sensor = ContactSensorConfig(condition=True, bandwidth_hz=100.0)
    config.sensor_faults = SensorFaultConfig(bias=[0, 0, 0, 0, 0, 0.5])
    config.start.in_contact = False
    config.supervision.enabled = True
    config.supervision.tare_time = 0.05
    build_scenario(config)
    _assert_one_wiring(connections, at_least=9)


@pytest.mark.parametrize("controller", kinematic_instability.CONTROLLERS)
def test_the_two_link_analysis_loop_is_wired_in_one_place(connections, controller):
    kinematic_instability.build_two_link_loop(controller)
    _assert_one_wiring(connections, at_least=6)


def test_a_real_arms_controller_side_is_wired_in_one_place(connections):
    pytest.importorskip("cmeel")                 # example-robot-data (the Panda) is a test extra
    from drake_hybrid.hardware.controller_side import build_controller_station
    from drake_hybrid.hardware.panda import panda_config, panda_table_task

    config = panda_config(panda_table_task(), duration=0.5)
    gains = HybridGains(velocity=[24.0], position=[96.0], force_proportional=[1.0], force_integral=[30.0])
    station = build_controller_station(config, DrakeLcm("memq://one_composition"), gain_changes=[(0.2, gains)])
    assert len(station.controllers) == 2
    _assert_one_wiring(connections, at_least=12)


def test_no_module_connects_a_law_by_hand():
    """The static side of the rule: in the package's source, only connect_hybrid_loop passes a port of a
    system named like a law (controller, law) to Connect."""
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for function in (node for node in ast.walk(tree) if isinstance(node, ast.FunctionDef)):
            if function.name == WIRING:
                continue
            for call in (node for node in ast.walk(function) if isinstance(node, ast.Call)):
                callee = call.func.attr if isinstance(call.func, ast.Attribute) else getattr(call.func, "id", "")
                if callee not in ("Connect", "guarded_connect", "_connect_shared"):
                    continue
                names = {node.id for arg in call.args for node in ast.walk(arg) if isinstance(node, ast.Name)}
                names |= {node.attr for arg in call.args for node in ast.walk(arg) if isinstance(node, ast.Attribute)}
                if names & {"controller", "law", "controllers"}:
                    offenders.append(f"{path.relative_to(PACKAGE)}:{call.lineno} in {function.name}")
    assert not offenders, offenders


# -- a user's own path job ------------------------------------------------------------------------------

PIPE = CylinderSurface(center=[0.45, 0.0, 0.1], axis=[0.0, 1.0, 0.0], radius=0.1)
GAINS = HybridGains(velocity=[30.0] * 3, position=[200.0] * 3, force_proportional=[0.5, 0.0, 0.0],
                    force_integral=[15.0, 1.0, 1.0], constraint_frequency=15.0)
SUPERVISION = SupervisionConfig(approach_speed=0.02, lift_height=0.01)


def _panda(plant):
    """The Panda of example-robot-data (a test extra) with the pad on its flange, by load_arm."""
    from drake_hybrid.hardware.panda import panda_arm
    return panda_arm().add_robot(plant)


@pytest.mark.slow          # 10 s of a job: about 25 s
def test_a_users_seven_joint_arm_rasters_a_pipe_and_lifts_off():
    """The case that decayed unseen: a 7-DOF arm from a model package on a pipe lying on its side, a raster
    along it, approach to lift-off, in the user's own builder. One second after the path's end the pad is
    off the surface; while on the path it follows it and presses with the commanded force."""
    pytest.importorskip("cmeel")                 # example-robot-data (the Panda) is a test extra
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    robot = _panda(plant)
    workpiece = add_rigid_workpiece(plant, Cylinder(0.1, 0.6),
                                    RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2), PIPE.center))
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    chart = PoseChart()
    space = ConstraintSpace(PIPE.offset_constraint(chart, 0.02), view_projection(chart, PIPE.default_view()))
    job = path_job(PIPE, 0.02, PathConfig(pattern=PatternConfig(kind="raster", size=[0.08, 0.04], spacing=0.04),
                                          speed=0.05, force=8.0))
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(_panda), gains=GAINS,
                                   mode="position-force", control_period=1e-3, path=job, supervision=SUPERVISION,
                                   initial_phase=ContactPhase.APPROACH)
    loggers = add_loggers(builder, hybrid)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    solve_path_start(diagram, context, hybrid, joint_guess=[0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.8])
    Simulator(diagram, context).AdvanceTo(job.duration(SUPERVISION, gap=0.005) + 1.0)
    log = read_log(loggers, context)
    assert log["path_done"][-1, 0] == 1 and log["lifting"][-1, 0] == 1
    assert abs(log["force"][-1, 0]) < 1e-9                       # off the pipe at the end
    phase = log["contact_phase"][:, 0]
    assert phase[0] == float(ContactPhase.APPROACH) and np.any(phase == float(ContactPhase.CONTACT))
    running = (log["path_progress"][:, 2] > 0.3) & (log["path_done"][:, 0] < 0.5)     # past the first transient
    assert np.abs(log["path_error"][running, :2]).max() < 1e-3                        # along the surface, m
    assert np.abs(log["force_error"][running, 0]).max() < 0.02 * 8.0
