"""Franka Panda tasks for the hardware loop: the Panda of ``example-robot-data`` (the bench and test extras)
with the pad tool at its TCP, as tutorials/06_your_own_robot.ipynb builds it.

``panda_drum_task()``   the pad on a horizontal drum (cylinder, axis along world y): m = 1
                        (the drum's normal), k = 5, as in tutorial 06.
``panda_table_task()``  the pad on a table top (a plane, z up): m = 1 (z), k = 5.

Both are registered by name (``panda-drum``, ``panda-table``) the first time they are asked for,
and ``panda_config(task)`` is the run both tests and ``drake-hybrid hardware`` use.
"""

import importlib.metadata
import logging
from pathlib import Path

import numpy as np
import sympy

from pydrake.geometry import Box, Cylinder
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.constraints import surface_constraint
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.projections import ConstraintSpace, GivenVelocityProjection
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.registry import get_task, register_task
from drake_hybrid.tasks.robots import load_arm

PAD_RADIUS = 0.02
DRUM_AXIS, DRUM_RADIUS = np.array([0.5, 0.0, 0.2]), 0.15
TABLE_TOP, TABLE_X = 0.1, 0.5
_ARMS = {}


def panda_urdf():
    """panda.urdf of the example-robot-data package (the bench or test extra: pip install ".[bench]")."""
    try:
        share = Path(importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data"))
    except importlib.metadata.PackageNotFoundError:
        raise ConfigError("task: the Panda tasks need the example-robot-data package (the bench extra): from a "
                          "clone pip install \".[bench]\", from PyPI pip install \"drake-hybrid[bench]\"") from None
    return share / "robots/panda_description/urdf/panda.urdf"


def panda_arm():
    """The Panda made usable by load_arm (fingers welded, pad at panda_hand_tcp), loaded once."""
    if "panda" not in _ARMS:
        # Drake warns once per joint that it ignores the URDF's <safety_controller> tags.
        logging.getLogger("drake").addFilter(lambda record: "safety_controller" not in record.getMessage())
        _ARMS["panda"] = load_arm(panda_urdf(), flange="panda_link8", tool_frame="panda_hand_tcp")
    return _ARMS["panda"]


def _registered(name, make):
    try:
        return get_task(name)
    except ValueError:
        return register_task(make())


def _five_free_rows(chart, constraint, name):
    E_p = GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0), name="(vx, vy, wx, wy, wz)")
    return ConstraintSpace(constraint, E_p)


def panda_drum_task():
    """The Panda pressing on a drum and sliding along x (tutorial 06), registered as 'panda-drum'."""
    def make():
        chart = PoseChart()
        drum = surface_constraint(chart, lambda p: sympy.sqrt((p[0] - DRUM_AXIS[0])**2 + (p[2] - DRUM_AXIS[2])**2)
                                  - (DRUM_RADIUS + PAD_RADIUS), name="drum", normal_rows=False)
        x0 = -0.05
        start = RigidTransform(RotationMatrix.MakeXRotation(np.pi),
                               DRUM_AXIS + [x0, 0.0, np.sqrt((DRUM_RADIUS + PAD_RADIUS)**2 - x0**2)])
        return CustomTask(
            "panda-drum", add_robot=panda_arm().add_robot,
            add_workpiece=lambda plant: add_rigid_workpiece(
                plant, Cylinder(DRUM_RADIUS, 0.6), RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2), DRUM_AXIS),
                name="drum"),
            constraint_space=_five_free_rows(chart, drum, "drum"), start_pose=start,
            joint_guess=[0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.8],
            labels={"velocity": ["v_x", "v_y", "w_x", "w_y", "w_z"],
                    "velocity_units": "m/s | m/s | rad/s | rad/s | rad/s",
                    "force": ["F (drum normal)"], "force_units": "N"})
    return _registered("panda-drum", make)


def panda_table_task():
    """The Panda pressing on a table top and sliding along y, registered as 'panda-table'."""
    def make():
        chart = PoseChart()
        table = surface_constraint(chart, lambda p: p[2] - (TABLE_TOP + PAD_RADIUS), name="table", normal_rows=False)
        start = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [TABLE_X, -0.05, TABLE_TOP + PAD_RADIUS])
        return CustomTask(
            "panda-table", add_robot=panda_arm().add_robot,
            add_workpiece=lambda plant: add_rigid_workpiece(
                plant, Box(0.6, 0.6, 0.05), RigidTransform([TABLE_X, 0.0, TABLE_TOP - 0.025]), name="table"),
            constraint_space=_five_free_rows(chart, table, "table"), start_pose=start,
            joint_guess=[0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.8],
            labels={"velocity": ["v_x", "v_y", "w_x", "w_y", "w_z"],
                    "velocity_units": "m/s | m/s | rad/s | rad/s | rad/s",
                    "force": ["F (table normal)"], "force_units": "N"})
    return _registered("panda-table", make)


def panda_config(task, duration=1.0, wrist_sensor=True, speed=0.05):
    """The run of the hardware tests: position-force, ``speed`` (m/s) along the surface, 10 N, tutorial 06's
    gains, 1 kHz plant and controller; the F/T sensor in the wrist weld (``wrist_sensor``) or the
    ideal contact sensor (for the external-torque path)."""
    velocity = [speed, 0.0, 0.0, 0.0, 0.0] if task.name == "panda-drum" else [0.0, speed, 0.0, 0.0, 0.0]
    config = task.default_config(
        desired_velocity=velocity, desired_force=[10.0], mode="position-force", duration=duration,
        gains=HybridGains(velocity=[16.0], position=[48.0], force_proportional=[0.5], force_integral=[15.0]))
    if wrist_sensor:
        config.sensor = WristSensorConfig()
        # A real F/T sensor's driver reports the tool's own inertia too: the paper's form, which does
        # not cancel F_v (scenario.config: compensate_tangential_force needs the tool's inertia removed).
        config.compensate_tangential_force = False
    else:
        # A driver estimates the external torque from the current state: the simulated one reads the
        # plant's unsampled ports (the current step's contact forces), and so does the directly wired run
        # it is compared with (tasks.plant.build_plant).
        config.plant.use_sampled_output_ports = False
    return config
