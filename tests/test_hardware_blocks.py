"""The controller side's small blocks against their definitions, on plants of their own: the driver's
gravity convention (made of Drake's systems), the F/T conditioning (one rotation of the sensor frame
and the fixed shifts of its tool), the status message's validation."""

import math

import numpy as np
import pytest
from drake import lcmt_panda_status
from hypothesis import given, settings
from hypothesis import strategies as st

from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RevoluteJoint, RotationalInertia, SpatialInertia, WeldJoint

from drake_hybrid.hardware.command import DriverGravityCompensation
from drake_hybrid.hardware.messages import Rejection
from drake_hybrid.hardware.watchdog import status_fields
from drake_hybrid.hardware.wrench import ForceTorqueConditioning

FINITE = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False, allow_infinity=False)


def arm_with_tool(reverse_actuators=False):
    """A 3-joint arm (links about z, y, x) with a tool welded to its last link, offset and turned; its
    actuators in joint order or reversed (a permutation actuation matrix). Returns (plant, weld)."""
    plant = MultibodyPlant(0.0)
    parent = plant.world_body()
    links = []
    for index, axis in enumerate(([0, 0, 1], [0, 1, 0], [1, 0, 0])):
        link = plant.AddRigidBody(f"link{index}", SpatialInertia.MakeFromCentralInertia(
            1.0 + index, [0.05, 0.01 * index, 0.2], RotationalInertia(0.02, 0.02, 0.003)))
        plant.AddJoint(RevoluteJoint(f"joint{index}", parent.body_frame(), link.body_frame(), axis))
        links.append(link)
        parent = link
    tool = plant.AddRigidBody("tool", SpatialInertia.MakeFromCentralInertia(
        0.7, [0.01, -0.02, 0.05], RotationalInertia(7e-4, 7e-4, 3e-4)))
    weld = plant.AddJoint(WeldJoint("tool_weld", links[-1].body_frame(), tool.body_frame(),
                                    RigidTransform(RollPitchYaw(0.3, -0.2, 0.5), [0.02, 0.01, 0.4])))
    joints = [plant.GetJointByName(f"joint{index}") for index in range(3)]
    for joint in reversed(joints) if reverse_actuators else joints:
        plant.AddJointActuator(f"{joint.name()}_motor", joint)
    plant.Finalize()
    return plant, weld


@pytest.mark.parametrize("reverse_actuators", [False, True])
@pytest.mark.parametrize("sign", [-1, 1])
def test_driver_gravity_adds_the_signed_holding_torque_in_actuation_order(sign, reverse_actuators):
    plant, _ = arm_with_tool(reverse_actuators)
    block = DriverGravityCompensation(plant, sign)
    context = block.CreateDefaultContext()
    plant_context = plant.CreateDefaultContext()
    actuation_from_torque = np.linalg.inv(plant.MakeActuationMatrix())
    assert np.array_equal(np.abs(actuation_from_torque), np.eye(3)) != reverse_actuators
    rng = np.random.default_rng(7)
    for _ in range(20):
        state, torque = rng.normal(size=6), rng.normal(size=3)
        block.GetInputPort("estimated_state").FixValue(context, state)
        block.GetInputPort("torque").FixValue(context, torque)
        plant.SetPositionsAndVelocities(plant_context, state)
        holding = actuation_from_torque @ -plant.CalcGravityGeneralizedForces(plant_context)
        np.testing.assert_array_equal(block.gravity(context), holding)
        np.testing.assert_array_equal(block.GetOutputPort("torque").Eval(context), torque + sign * holding)


def test_driver_gravity_takes_only_a_sign():
    plant, _ = arm_with_tool()
    with pytest.raises(ValueError, match="sign must be -1 or \\+1"):
        DriverGravityCompensation(plant, 2)


@settings(max_examples=40, deadline=None)
@given(state=st.lists(FINITE, min_size=6, max_size=6), reading=st.lists(FINITE, min_size=6, max_size=6),
       point=st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3), on_tool=st.booleans())
def test_force_torque_conditioning_is_the_shifted_rotated_reading_less_the_tool_weight(state, reading, point, on_tool):
    """wrench = shift_{S->P}(R_WS (reading - bias)) - shift_{com->P}([0; m g]), computed here from the plant's
    own poses and np.cross, for P on the tool or on the wrist (both welded to the sensor)."""
    plant, weld = arm_with_tool()
    frame = weld.child_body().body_frame() if on_tool else weld.parent_body().body_frame()
    bias = np.array([0.1, -0.2, 0.05, 1.0, -0.5, 2.0])
    block = ForceTorqueConditioning(plant, weld, frame, point, bias)
    context = block.CreateDefaultContext()
    block.GetInputPort("estimated_state").FixValue(context, state)
    block.GetInputPort("sensor_wrench").FixValue(context, reading)
    plant_context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(plant_context, state)
    world = plant.world_frame()
    X_WS = weld.frame_on_child().CalcPoseInWorld(plant_context)
    tool = weld.child_body()
    p_WP = plant.CalcPointsPositions(plant_context, frame, np.asarray(point), world).ravel()
    p_Wcom = plant.CalcPointsPositions(plant_context, tool.body_frame(), tool.default_com(), world).ravel()
    R_WS = X_WS.rotation().matrix()
    corrected = np.asarray(reading) - bias
    torque, force = R_WS @ corrected[:3], R_WS @ corrected[3:]
    weight = tool.default_mass() * plant.gravity_field().gravity_vector()
    expected = np.concatenate([torque - np.cross(p_WP - X_WS.translation(), force) + np.cross(p_WP - p_Wcom, weight),
                               force - weight])
    np.testing.assert_allclose(block.GetOutputPort("wrench").Eval(context), expected, rtol=0, atol=1e-12)


def test_force_torque_conditioning_refuses_a_point_not_fixed_to_the_sensor():
    plant, weld = arm_with_tool()
    with pytest.raises(ValueError, match="'link0', which is not welded to the sensor's tool 'tool'"):
        ForceTorqueConditioning(plant, weld, plant.GetBodyByName("link0").body_frame(), [0, 0, 0])


def panda_status(values, n=7, utime=1000):
    message = lcmt_panda_status()
    message.utime, message.num_joints = utime, n
    message.joint_position, message.joint_velocity, message.joint_torque_external = (
        list(values[:n]), list(values[n:2 * n]), list(values[2 * n:]))
    return message


@settings(max_examples=60, deadline=None)
@given(values=st.lists(FINITE, min_size=21, max_size=21), bad=st.sampled_from([math.nan, math.inf, -math.inf]),
       where=st.integers(0, 20))
def test_a_status_is_accepted_exactly_or_rejected_for_one_non_finite_entry(values, bad, where):
    stamp, fields, rejection = status_fields(panda_status(values), 7)
    assert (stamp, rejection) == (1e-3, Rejection.NONE)
    assert fields.dtype == float and fields.tolist() == [float(x) for x in values]
    broken = list(values)
    broken[where] = bad
    assert status_fields(panda_status(broken), 7)[1:] == (None, Rejection.NON_FINITE)


def test_a_status_of_the_wrong_size_or_none_yet():
    assert status_fields(lcmt_panda_status(), 7) is None
    assert status_fields(panda_status([0.0] * 18, n=6), 7)[1:] == (None, Rejection.WRONG_SIZE)
    short = panda_status([0.0] * 21)
    short.joint_torque_external = [0.0] * 6
    assert status_fields(short, 7)[1:] == (None, Rejection.WRONG_SIZE)
