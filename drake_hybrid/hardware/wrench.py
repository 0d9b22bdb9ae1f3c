"""The controller's ``measured_wrench`` from what a real arm reports: the wrench [n; f] on the robot
from the environment, at the end-effector point P, in world (the convention of systems.wrench_frames).

``ForceTorqueConditioning``
    from an F/T sensor in the weld between wrist and tool (``lcmt_force_torque``, sensor frame S):
    remove the bias, rotate to world and shift to P, remove the tool's weight::

        wrench = shift_{S->P}(R_WS (reading - bias)) - shift_{com->P}([0; m_t g])

    the same conditioning as the simulated ``WristForceTorqueSensor`` (whose reading is the
    negated reaction on the tool; static compensation), here from the measured joints through the
    controller's plant.
``ExternalTorqueWrench``
    without an F/T sensor: the driver's external-torque estimate tau_ext = J_P^T F mapped back,
    F = argmin |J_P^T F - tau_ext| (J_P the 6 x n spatial Jacobian at P in world; exact for a
    contact at the pad and n >= 6 with J_P of full rank).
"""

import numpy as np

from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import LeafSystem

from drake_hybrid.core.kinematics import declare_plant_context_cache, resolve_frame


class ForceTorqueConditioning(LeafSystem):
    """The contact wrench at P from an F/T reading in the wrist weld.

    .. pydrake_system::

        name: ForceTorqueConditioning
        input_ports:
        - sensor_wrench
        - estimated_state
        output_ports:
        - wrench

    ``sensor_wrench`` is [t; f] in the sensor frame S (the weld's child frame): the wrench the tool
    exerts on the wrist, at S's origin. Args: ``plant`` (the controller's, finalized),
    ``weld_joint`` (the WeldJoint between wrist and tool in it), ``end_effector_frame`` and
    ``end_effector_point`` (P), ``bias`` ([t; f] the sensor reads with no load, subtracted).
    """

    def __init__(self, plant, weld_joint, end_effector_frame, end_effector_point, bias=None):
        LeafSystem.__init__(self)
        self._plant = plant
        self._sensor_frame = weld_joint.frame_on_child()
        tool = weld_joint.child_body()
        frame = resolve_frame(plant, end_effector_frame)
        if frame.body() not in plant.GetBodiesWeldedTo(tool):
            raise ValueError(f"ForceTorqueConditioning: the end-effector frame '{frame.name()}' is on body "
                             f"'{frame.body().name()}', which is not welded to the sensor's tool '{tool.name()}'; "
                             "a wrist F/T sensor measures the wrench at a point of its tool")
        self._gravity = plant.gravity_field().gravity_vector()
        self._weight = (tool.default_mass() * self._gravity).tolist()
        self.bias = np.zeros(6) if bias is None else np.asarray(bias, dtype=float)
        # P and the tool's centre of mass are fixed in S (their bodies are welded to the sensor), so the
        # two shifts are S's rotation of constant vectors: a = p_SP, b = p_SP - p_Scom (in S).
        context = plant.CreateDefaultContext()
        p_SP = plant.CalcPointsPositions(context, frame, np.asarray(end_effector_point, dtype=float),
                                         self._sensor_frame).ravel()
        p_Scom = plant.CalcPointsPositions(context, tool.body_frame(), tool.default_com(), self._sensor_frame).ravel()
        self._shifts_S = np.concatenate([p_SP, p_SP - p_Scom])          # [a_S; b_S]
        self._wrench_port = self.DeclareVectorInputPort("sensor_wrench", 6)
        self._state_port = self.DeclareVectorInputPort("estimated_state", plant.num_multibody_states())
        self._context_cache = declare_plant_context_cache(self, plant, self._state_port)
        self.DeclareVectorOutputPort("wrench", 6, self._calc)

    def _calc(self, context, output):
        # The formula of the module docstring, rotated to world in one product: [t; f; a_S; b_S] R_WS^T;
        # the cross products written out (np.cross and np.concatenate cost more than the arithmetic).
        R_WS = self._sensor_frame.CalcRotationMatrixInWorld(self._context_cache.Eval(context)).matrix()
        rows = np.concatenate([self._wrench_port.Eval(context) - self.bias, self._shifts_S]).reshape(4, 3)
        (tx, ty, tz), (fx, fy, fz), (ax, ay, az), (bx, by, bz) = np.dot(rows, R_WS.T).tolist()
        wx, wy, wz = self._weight                           # m_t g
        # shift(reading_W, a) - shift([0; w], b): n = t - a x f - (0 - b x w), f = f - w
        output.SetFromVector([tx - (ay * fz - az * fy) - (0.0 - (by * wz - bz * wy)),
                              ty - (az * fx - ax * fz) - (0.0 - (bz * wx - bx * wz)),
                              tz - (ax * fy - ay * fx) - (0.0 - (bx * wy - by * wx)),
                              fx - wx, fy - wy, fz - wz])


class ExternalTorqueWrench(LeafSystem):
    """The contact wrench at P from the driver's external joint torques, F = (J_P^T)^+ tau_ext.

    .. pydrake_system::

        name: ExternalTorqueWrench
        input_ports:
        - torque_external
        - estimated_state
        output_ports:
        - wrench

    ``torque_external`` is the generalized force of the environment on the arm (sign as the
    simulated driver sends it: check a real driver's sign with a push by hand, docs/hardware.md).
    """

    def __init__(self, plant, end_effector_frame, end_effector_point):
        LeafSystem.__init__(self)
        self._plant = plant
        self._frame = resolve_frame(plant, end_effector_frame)
        self._point = np.asarray(end_effector_point, dtype=float)
        self._torque_port = self.DeclareVectorInputPort("torque_external", plant.num_velocities())
        self._state_port = self.DeclareVectorInputPort("estimated_state", plant.num_multibody_states())
        self._context_cache = declare_plant_context_cache(self, plant, self._state_port)
        self.DeclareVectorOutputPort("wrench", 6, self._calc)

    def _calc(self, context, output):
        plant_context = self._context_cache.Eval(context)
        world = self._plant.world_frame()
        J = self._plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, self._frame, self._point,
                                                    world, world)
        output.SetFromVector(np.linalg.lstsq(J.T, self._torque_port.Eval(context), rcond=None)[0])
