"""Naming unstable modes (analysis.modes): the slow drift of velocity-force mode on a curved workpiece.

The Panda (example-robot-data) presses its ball pad with 10 N on a horizontal cylinder of radius
5 cm. In velocity-force mode the positions along the velocity rows are unregulated by design (zero
eigenvalues); the tessellated pad and cylinder give a tangential contact stiffness slightly
different from the geometric F/rho that the law cancels, which moves one of those zeros to
+0.20 1/s here in the paper's form (+0.76 with a 5 mm drum mesh; docs/drake_notes.md). Position-force
mode regulates it; the default law cancels the measured F_v (control.law.tangential_compensation),
which removes it.
"""

import importlib.metadata
import json
import logging
from pathlib import Path

import numpy as np
import pytest
import sympy

from pydrake.geometry import Cylinder
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.analysis.modes import UNSTABLE_RATE
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.scenario.custom import (CustomTask, add_actuators, add_rigid_workpiece, attach_pad_tool,
                                          urdf_effort_limits, weld_joints)
from drake_hybrid.scenario.tasks import register_task

logging.getLogger("drake").addFilter(lambda record: "safety_controller" not in record.getMessage())
SHARE = Path(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
PANDA = SHARE / "robots/panda_description/urdf/panda_collision.urdf"
AXIS, RADIUS, PAD_RADIUS, X0 = np.array([0.5, 0.0, 0.2]), 0.05, 0.02, -0.02


def add_panda(plant):
    parser = Parser(plant)
    parser.package_map().Add("example-robot-data", str(SHARE))
    panda = parser.AddModels(str(PANDA))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("panda_link0", panda))
    weld_joints(plant, ["panda_finger_joint1", "panda_finger_joint2"], panda)
    add_actuators(plant, panda, urdf_effort_limits(PANDA))
    return attach_pad_tool(plant, panda, "panda_hand_tcp")


def add_small_drum(plant):
    X_WDrum = RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2), AXIS)      # axis along world y
    return add_rigid_workpiece(plant, Cylinder(RADIUS, 0.6), X_WDrum, name="small_drum")


@pytest.fixture(scope="module")
def small_drum_task():
    chart = PoseChart()
    drum = surface_constraint(chart, lambda p: sympy.sqrt((p[0] - AXIS[0])**2 + (p[2] - AXIS[2])**2)
                              - (RADIUS + PAD_RADIUS), name="small drum", normal_rows=False)
    space = ConstraintSpace(drum, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0), name="rest"))
    start = RigidTransform(RotationMatrix.MakeXRotation(np.pi),
                           AXIS + [X0, 0.0, np.sqrt((RADIUS + PAD_RADIUS)**2 - X0**2)])
    return register_task(CustomTask("test-panda-small-drum", add_robot=add_panda, add_workpiece=add_small_drum,
                                    constraint_space=space, start_pose=start,
                                    joint_guess=[0.0, -0.3, 0.0, -2.2, 0.0, 1.9, 0.8]))


def config_for(task, mode, compensate_tangential_force=True):
    config = task.default_config(desired_velocity=[0.05, 0.0, 0.0, 0.0, 0.0], desired_force=[10.0], mode=mode,
                                 gains=HybridGains(velocity=[16.0], position=[48.0], force_proportional=[0.5],
                                                   force_integral=[15.0]))
    config.compensate_tangential_force = compensate_tangential_force
    return config


def test_velocity_mode_drift_on_a_small_drum_is_named_with_its_cause(small_drum_task):
    """The paper's form (F_v left in): the drift appears and is named."""
    dut = linearize_continuous(config_for(small_drum_task, "velocity-force", compensate_tangential_force=False))
    assert len(dut.unstable_modes) == 1
    (mode,) = dut.unstable_modes
    # measured 0.2025 1/s with the default 2.5 mm mesh of this drum (0.7593 with a 5 mm one)
    assert mode.eigenvalue.real == pytest.approx(0.2025, abs=0.01)
    assert mode.eigenvalue.imag == 0.0
    assert mode.dominant == "velocity rows" and mode.shares["velocity rows"] > 0.9
    assert "drift of the positions the velocity rows leave unregulated" in mode.likely_cause
    assert "tessellated" in mode.likely_cause and mode.stiffness > 0
    assert "unstable mode 0.203" in mode.summary()
    assert json.loads(json.dumps(mode.as_dict()))["dominant"] == "velocity rows"
    # Every other mode is below the threshold.
    assert np.sort(dut.eigenvalues.real)[-2] < UNSTABLE_RATE


def test_position_mode_regulates_the_drift(small_drum_task):
    dut = linearize_continuous(config_for(small_drum_task, "position-force"))
    assert dut.unstable_modes == []
    assert dut.eigenvalues.real.max() < UNSTABLE_RATE                      # measured 2e-14 1/s


def test_the_default_law_cancels_the_measured_tangential_force_and_the_drift_with_it(small_drum_task):
    """Velocity-force mode with the law's default F_v compensation: the zero of the unregulated
    tangential position stays at 0 (the tessellation's dk acts only through the sensor path)."""
    dut = linearize_continuous(config_for(small_drum_task, "velocity-force"))
    assert dut.unstable_modes == []
    assert dut.eigenvalues.real.max() < UNSTABLE_RATE                      # measured 1.7e-11 1/s
    assert dut.jacobian_check.agrees


def test_a_wrist_sensor_without_tool_inertia_compensation_is_refused_with_the_cancellation():
    from drake_hybrid.core.errors import ConfigError
    from drake_hybrid.scenario.tasks import get_task

    config = get_task("crank-turning").default_config()
    assert config.compensate_tangential_force is False          # the crank keeps the paper's form
    config.compensate_tangential_force = True
    with pytest.raises(ConfigError, match="sensor.compensate_tool_inertia: true"):
        config.validate()
    config.sensor.compensate_tool_inertia = True
    config.validate()
