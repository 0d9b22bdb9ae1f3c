"""The one handle of a hybrid loop: what a composition added around one controller.

``station.loop.add_hybrid_controller`` (your station), ``scenario.builder.build_scenario`` (a task's
run, a ``tasks.task.Scenario``) and ``hardware.controller_side.build_controller_station`` (a real
arm's controller side, a ``ControllerStation``) all return a ``HybridSystems``: the same fields, the
same ports, read the same way by the start (``station.start``), the loggers (``station.loggers``) and
the analysis. The two compositions that know more add it in a subclass.
"""

from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple, Union, cast

from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram, OutputPort, System
from pydrake.systems.primitives import VectorLogSink

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.supervision import ContactSupervisor
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.station.path_job import PathJob
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.station.sensing import WrenchSensor
from drake_hybrid.systems.contact_patch import ContactPatchSensor
from drake_hybrid.systems.faults import SensorFaultInjector
from drake_hybrid.systems.low_pass_filter import LowPassFilter
from drake_hybrid.systems.wrench_conditioner import WrenchConditioner

# A logger of ``station.loggers.add_loggers``: a VectorLogSink, or (sink, columns) for a signal the
# controller's ``diagnostics`` port carries with others.
Logger = Union[VectorLogSink, Tuple[VectorLogSink, slice]]


@dataclass(kw_only=True)
class HybridSystems:
    """The systems and ports of one hybrid loop, by name.

    ``controller`` (a ``HybridController``, or a baseline with its ports), ``state`` (the output port of
    the arm's [q; v] the loop reads: the plant's, or a real arm's watchdog's), ``wrench_output`` (the
    port the controller reads the wrench from), ``actuation`` (the torque that leaves the loop: the
    controller's, or the gain selector's on a real arm); ``robot`` (RobotModel), ``controller_plant``
    (the controller's own model) and ``constraint_space``; on a simulated station also ``plant`` (the
    MultibodyPlant), ``sensor`` (ContactWrenchSensor or WristForceTorqueSensor), ``true_wrench`` (the
    sensor's own output) and ``kinematics`` (EndEffectorKinematics on ``plant``); the optional parts
    ``source`` (the command source, None when you wire the desired_* ports yourself),
    ``wrench_filter``, ``conditioner``, ``fault_injector``, ``supervisor`` (ContactSupervisor) and
    ``path`` (the PathJob the source runs), ``patch`` (the pad's ``ContactPatchSensor``); ``loggers``
    ({key: logger} of ``add_loggers``) and
    ``diagram`` (set once built, by the functions that take the built diagram)."""

    robot: RobotModel
    controller_plant: MultibodyPlant
    constraint_space: ConstraintSpace
    controller: HybridController        # or a baseline of control.baselines (the same ports)
    state: OutputPort
    wrench_output: OutputPort
    actuation: OutputPort
    plant: Optional[MultibodyPlant] = None
    sensor: Optional[WrenchSensor] = None
    true_wrench: Optional[OutputPort] = None
    kinematics: Optional[EndEffectorKinematics] = None
    source: Optional[System] = None
    wrench_filter: Optional[LowPassFilter] = None
    conditioner: Optional[WrenchConditioner] = None
    fault_injector: Optional[SensorFaultInjector] = None
    supervisor: Optional[ContactSupervisor] = None
    path: Optional[PathJob] = None
    patch: Optional[ContactPatchSensor] = None     # the pad's contact patch (station.sensing.add_contact_patch)
    loggers: Dict[str, Logger] = field(default_factory=dict)
    diagram: Optional[Diagram] = None

    def plant_context(self, root_context: Context) -> Context:
        """The simulated plant's mutable context in the diagram's ``root_context``."""
        plant = cast(MultibodyPlant, self.plant)       # a simulated station's (a real arm's has none)
        return plant.GetMyMutableContextFromRoot(root_context)
