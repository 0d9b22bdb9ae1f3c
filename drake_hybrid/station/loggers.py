"""Loggers of every signal of a hybrid loop, and the log they give.
"""

from typing import Dict, Optional, Tuple

from pydrake.systems.framework import Context, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from drake_hybrid.core.arguments import instance, nonnegative
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array
from drake_hybrid.station.handles import HybridSystems, Logger
from drake_hybrid.station.root_context import subsystem_context

# The log's keys (read_log; log.npz names a few otherwise), each (samples x size), with "t" the sample times.
LOG_KEYS = {
    "t": "sample times (s)",
    "velocity_error": "e_p' = E_p r-dot - r-dot_pd (k; each row in its own units)",
    "force_error": "e_f = F - F_d (m; zero on kinematic rows, NaN while the wrench is invalid)",
    "wrench_valid": "1 where the measured wrench was finite, 0 where not (then force, force_error and "
                    "tangential_force read NaN) (1)",
    "constraint_value": "C(r) (m; in C's units: a contact's compression, a weld's offset)",
    "projected_velocity": "r-dot_p = E_p r-dot (k)",
    "force": "F, the force on the robot in E_f's coordinates ([F_v; F] = E^-T w) (m)",
    "tangential_force": "F_v, the measured force along the velocity rows (k)",
    "position_error": "e_p, the integral of e_p' (k; zero in velocity-force mode)",
    "actuation": "the actuators' torques (n_u, N m or N, in the plant's actuator order)",
    "desired_velocity": "r-dot_pd (k)",
    "desired_force": "F_d (m)",
    "state": "[q; v] of the arm (2n, in the plant's joint order for robot.arm)",
    "wrench": "the wrench the controller reads: [torque; force] on the robot BY the environment at the "
              "end-effector point, world frame (6; N m, N), after the filter or conditioner",
    "true_wrench": "the sensor's own wrench, before faults, filter or conditioner (6; only when they differ)",
    "contact_phase": "the ContactSupervisor's phase (1; control.phases.ContactPhase values; only when supervised)",
    # A path job's (add_hybrid_controller(..., path=job)): the PathSource's outputs and the supervisor's lift-off.
    "reference_position": "the path's reference point, the pad centre's (3, m, world)",
    "reference_normal": "the surface's outward unit normal at the reference (3)",
    "path_error": "c - c_d: the pad centre's error against the reference point (3, m, world)",
    "path_progress": "[segment, arc length (m), path time (s; < 0 before the path starts)] (3)",
    "path_done": "1 once the path has ended (1)",
    "lifting": "1 while the supervisor lifts the pad off at the path's end (1)",
    # The pad's contact patch (HybridSystems.patch, station.sensing.add_contact_patch), held between its updates.
    "patch": "the contact patch: [centre of pressure's distance from the tool's axis (m), area (m^2), area over "
             "the tool's face (1), peak pressure (Pa), mean pressure (Pa), tilt against the patch's normal (rad), "
             "normal force (N), centre of pressure (3, world, m)] (10; systems.contact_patch.PATCH_FIELDS)",
}
PATH_LOGS = ("reference_position", "reference_normal", "path_error", "path_progress", "path_done")


def add_loggers(builder: DiagramBuilder, systems: HybridSystems,
                period: Optional[float] = None) -> Dict[str, Logger]:
    """Loggers for every signal of ``systems`` (a HybridSystems), keyed by ``LOG_KEYS``; a path job's
    reference, error and progress (and the supervisor's lift-off) too.

    ``period``: sample period (s); None logs every publish of the simulator's steps. A controller with
    ``sampled_diagnostics`` is logged from its ``diagnostics`` port (what each tick computed, read
    once). Returns {key: VectorLogSink or (sink, column slice)}, also kept as ``systems.loggers``;
    ``read_log`` turns it into arrays."""
    instance(builder, "builder", "add_loggers", DiagramBuilder)
    instance(systems, "systems", "add_loggers", HybridSystems, what="the HybridSystems of add_hybrid_controller")
    controller = systems.controller
    loggers: Dict[str, Logger] = {}
    period = nonnegative(0.0 if period is None else period, "period", "add_loggers", unit="s")
    if getattr(controller, "sampled_diagnostics", False):
        diagnostics = LogVectorOutput(controller.GetOutputPort("diagnostics"), builder, period)
        for name, columns in controller.diagnostic_slices().items():
            loggers[name] = (diagnostics, columns)
    else:
        for name in controller.diagnostic_slices():
            loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, period)
    loggers["position_error"] = LogVectorOutput(controller.GetOutputPort("position_error"), builder, period)
    loggers["actuation"] = LogVectorOutput(systems.actuation, builder, period)
    if systems.source is not None:
        for name in ("desired_velocity", "desired_force"):
            loggers[name] = LogVectorOutput(systems.source.GetOutputPort(name), builder, period)
    loggers["state"] = LogVectorOutput(systems.state, builder, period)
    loggers["wrench"] = LogVectorOutput(systems.wrench_output, builder, period)
    if systems.true_wrench is not None and systems.true_wrench is not systems.wrench_output:
        loggers["true_wrench"] = LogVectorOutput(systems.true_wrench, builder, period)
    if systems.supervisor is not None:
        loggers["contact_phase"] = LogVectorOutput(systems.supervisor.GetOutputPort("contact_phase"), builder, period)
    if systems.patch is not None:
        loggers["patch"] = LogVectorOutput(systems.patch.GetOutputPort("patch"), builder, period)
    if systems.path is not None and systems.source is not None:
        for name in PATH_LOGS:
            loggers[name] = LogVectorOutput(systems.source.GetOutputPort(name), builder, period)
        if systems.supervisor is not None:
            loggers["lifting"] = LogVectorOutput(systems.supervisor.GetOutputPort("lifting"), builder, period)
    systems.loggers.update(loggers)
    return loggers


def logged(loggers: Dict[str, Logger], root_context: Context, name: str,
           owner: str = "logged") -> Tuple[Array, Array]:
    """(times, samples x size) of logger ``name`` of ``loggers`` (``add_loggers``) in ``root_context`` (the
    root context of the diagram they were added to: ArgumentError naming ``owner`` otherwise)."""
    instance(loggers, "loggers", owner, dict, what="the dict of add_loggers")
    if name not in loggers:
        raise ArgumentError(f"{owner}: no logger '{name}'; these were logged: {', '.join(loggers)}")
    logger, columns = loggers[name], slice(None)
    if isinstance(logger, tuple):
        logger, columns = logger
    subsystem_context(logger, root_context, owner, "the diagram the loggers were added to")
    log = logger.FindLog(root_context)
    return log.sample_times(), log.data().T[:, columns]


def read_log(loggers: Dict[str, Logger], root_context: Context) -> Dict[str, Array]:
    """{key: array} of every logger of ``add_loggers`` in ``root_context``, with "t" (the sample times of
    the first), keyed by ``LOG_KEYS`` (log.npz calls a few otherwise: velocity, constraint, torque, q and v)."""
    instance(loggers, "loggers", "read_log", dict, what="the dict of add_loggers")
    log: Dict[str, Array] = {}
    for name in loggers:
        times, values = logged(loggers, root_context, name, "read_log")
        log.setdefault("t", times)
        log[name] = values
    return log
