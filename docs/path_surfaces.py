"""Path jobs on every surface kind, from a task file and from your own diagram, on arms the package does not ship.

The acceptance runs of ``docs/paths.py``'s section "Every surface kind" (``python docs/paths.py --surfaces``):

* the surfaces: a plane tilted by 15 degrees, a sphere (radius 15 cm), a cylinder lying along y (radius 10 cm)
  with the path 11 to 22 degrees off its top line, and a height map (a 3 cm Gaussian bump, 41 x 41 samples,
  the path on its flank);
* the routes: a task file (written here; the UR10 of example-robot-data by ``robot.loader``) run by
  ``simulate``, and a user's own diagram (the Franka Panda of example-robot-data by ``load_arm``, the blocks of
  ``station``) run by Drake's Simulator;
* the job: the guarded approach from 5 mm above the path's first point at 2 cm/s, 0.3 s pressing there, two 3 cm
  raster lines 1.5 cm apart at 5 cm/s and 0.5 m/s^2 (three segments), 10 N, the lift-off; position-force mode,
  the gains of docs/paths.md (five design time constants: 0.5 s); the plant and the controller at 1 kHz.

Measured per job: the normal force from the logged wrench (the sensor's own) along the true normal at the pad
centre (``Surface.closest_point`` of the pad centre from the logged joint positions: the part's normal at the
contact), against the command over each segment's settled part (its start + five design time constants to its
end), beside the path report's figure (``experiments.path_report``: the wrench along the reference's normal);
and the continuous loop held at h = 0, 0.25, 0.5, 0.75 and 1 of the path with the force by arc length from 6 to
14 N (``path.hold_at``): every designed eigenvalue against its linearized partner.
"""

import importlib.metadata
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.analysis.design import design_time_constant
from drake_hybrid.analysis.linearization import linearize_at_contact, linearize_continuous
from drake_hybrid.control.gains import ControlMode, HybridGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, SphereSurface, view_projection
from drake_hybrid.experiments.path_report import path_report
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.hardware.panda import panda_arm
from drake_hybrid.station.arm import robot_plant
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.contact_start import solve_path_start
from drake_hybrid.station.loggers import add_loggers, read_log
from drake_hybrid.station.loop import add_hybrid_controller
from drake_hybrid.station.parsing import models_directory
from drake_hybrid.station.path_config import ForcePointConfig, PathConfig, PatternConfig, ViewConfig
from drake_hybrid.station.path_job import path_job
from drake_hybrid.tasks.path import job_duration, with_path
from drake_hybrid.tasks.robots import load_arm
from drake_hybrid.tasks.task_file import load_task_file
from drake_hybrid.tasks.task_file_surface import SurfaceSpec, add_surface_geometry

SHARE = Path(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
UR10 = "package://example-robot-data/robots/ur_description/urdf/ur10_robot.urdf"
BUMP = models_directory() / "tasks" / "bump_part.csv"
PAD = 0.02
FORCE = 10.0
HOLDS = (0.0, 0.25, 0.5, 0.75, 1.0)
RAMP = (6.0, 14.0)                      # N: the force by arc length of the linearized jobs, from the start to the end
GAINS = dict(velocity=[30.0] * 3, position=[200.0] * 3, force_proportional=[0.5, 0.0, 0.0],
             force_integral=[15.0, 1.0, 1.0], constraint_frequency=15.0)
RASTER = dict(kind="raster", size=[0.03, 0.015], spacing=0.015, direction="u")


def surfaces(x0, top):
    """{kind: (the SurfaceSpec of a task file, the pattern's center (u, v) in the surface's default view)} with
    the workpiece's top near (x0, 0, top)."""
    tilt = math.radians(15.0)
    return {
        "tilted plane": (SurfaceSpec(kind="plane", center=[x0, 0.0, top], normal=[-math.sin(tilt), 0.0, math.cos(tilt)],
                                     size=[0.3, 0.3, 0.02], offset=PAD), [0.0, 0.0]),
        "sphere": (SurfaceSpec(kind="sphere", center=[x0, 0.0, top - 0.15], radius=0.15, offset=PAD), [0.02, 0.02]),
        # Seen from above, u along the axis (y), v = -x: the lines 2.25 to 3.75 cm off the top line (13 to 22 deg).
        "cylinder": (SurfaceSpec(kind="cylinder", center=[x0, 0.0, top - 0.1], axis=[0.0, 1.0, 0.0], radius=0.1,
                                 length=0.4, offset=PAD), [0.0, 0.03]),
        "height map": (SurfaceSpec(kind="height_map", file=str(BUMP), spacing=[0.004, 0.004], origin=[-0.08, -0.08],
                                   offset=PAD), [0.02, 0.01]),
    }


def surface_of(spec, X_WM):
    """The core.surfaces Surface of ``spec`` (the height map placed at ``X_WM``)."""
    if spec.kind == "plane":
        return PlaneSurface(spec.center, spec.normal)
    if spec.kind == "sphere":
        return SphereSurface(spec.center, spec.radius)
    if spec.kind == "cylinder":
        return CylinderSurface(spec.center, spec.axis, spec.radius, spec.length)
    heights = HeightMap.from_file(spec.file, spec.spacing, spec.origin)
    return HeightMapSurface(heights, X_WM, name="bump")


def path_settings(center, hold_at=-1.0, ramp=None, length=None):
    settings = PathConfig(pattern=PatternConfig(center=list(center), **RASTER), speed=0.05, acceleration=0.5,
                          force=FORCE, dwell=0.3, view=ViewConfig(), hold_at=hold_at)
    if ramp is not None:
        settings.force_by_arc_length = [ForcePointConfig(0.0, ramp[0]), ForcePointConfig(length, ramp[1])]
    return settings


# -- the figures of a run ---------------------------------------------------------------------------------

def measured_normal_force(log, plant, robot, surface):
    """The sensor's wrench along the true normal at the pad centre (N per sample): the pad centre from the
    logged joint positions (``plant`` the controller's model), the normal the part's at its closest point."""
    context = plant.CreateDefaultContext()
    frame = plant.GetFrameByName(robot.end_effector_frame)
    point = np.asarray(robot.end_effector_point, dtype=float)
    n = plant.num_positions()
    wrench = np.asarray(log["true_wrench"] if "true_wrench" in log else log["wrench"])
    force = np.empty(len(log["t"]))
    positions = np.asarray(log["q"]) if "q" in log else np.asarray(log["state"])[:, :n]   # simulate's, read_log's
    for i, q in enumerate(positions):
        plant.SetPositions(context, q)
        centre = frame.CalcPoseInWorld(context).multiply(point)
        force[i] = wrench[i, 3:] @ surface.closest_point(centre)[1]
    return force


def force_figures(log, report, measured):
    """Per segment (settled part): max |F_n - F_d| / F_d (%) from ``measured`` and the report's figure."""
    t, desired = np.asarray(log["t"]), np.asarray(log["desired_force"])[:, 0]
    rows = []
    for segment in report.segments:
        window = (t >= segment.start + report.settle_time_per_segment_s) & (t <= segment.end)
        if not np.any(window):             # a segment shorter than five time constants (the step between lines)
            continue
        error = 100.0 * np.max(np.abs(measured[window] - desired[window]) / desired[window])
        rows.append({"segment": segment.segment, "measured_percent": float(error),
                     "report_percent": segment.max_force_error_percent,
                     "mean_normal_force": float(np.mean(measured[window]))})
    return rows


def eigenvalue_figures(linear):
    return {"residual": float(linear.equilibrium_residual), "matched": bool(linear.match.matched),
            "worst_percent": float(100 * np.max(linear.match.relative_error)),
            "unstable": len(linear.unstable_modes), "largest_real": float(np.max(linear.eigenvalues.real)),
            "jacobian": linear.jacobian_check.used}


# -- the task-file route: the UR10 ---------------------------------------------------------------------------

TASK_FILE = """name: {name}
description: UR10 (example-robot-data) rastering a {kind} (docs/path_surfaces.py)
robot:
  loader: {{path: {arm}, flange: tool0, collision: drop}}
workpiece:
  surface: {surface}
chart: {{kind: pose}}
start:
  joint_guess: {guess}
config:
  mode: position-force
  duration: 5.0
  gains: {gains}
  start: {{in_contact: false, gap: 0.005}}
  supervision: {{enabled: true, approach_speed: 0.02, lift_height: 0.01}}
  path:
    pattern: {pattern}
    speed: 0.05
    acceleration: 0.5
    force: {force}
    dwell: 0.3
"""


def _flow(values):
    """A YAML flow mapping of ``values`` (numbers, lists, strings)."""
    return "{" + ", ".join(f"{key}: {value!r}".replace("'", '"') for key, value in values.items()) + "}"


def task_file_job(kind, spec, center, folder, arm):
    """(figures) of the job on ``kind`` from a task file for the UR10: written to ``folder``, its joint guess
    from ``LoadedArm.find_joint_guess`` at the path's first point."""
    X_WM = RigidTransform([0.7, 0.0, 0.1])
    surface = surface_of(spec, X_WM)
    settings = path_settings(center)
    job = path_job(surface, PAD, settings)
    guess = arm.find_joint_guess(job.pose_at_depth(-0.005), seeds=8).positions
    fields = {"plane": ("center", "normal", "size"), "sphere": ("center", "radius"),
              "cylinder": ("center", "axis", "radius", "length"), "height_map": ("file", "spacing", "origin")}
    values = dict({"kind": spec.kind, "offset": PAD}, **{name: getattr(spec, name) for name in fields[spec.kind]})
    surface_text = _flow(values)
    if spec.kind == "height_map":
        surface_text = surface_text[:-1] + ", X_WM: {translation: [0.7, 0.0, 0.1]}}"
    name = f"ur10-{kind.replace(' ', '-')}"
    path = Path(folder) / f"{name}.yaml"
    path.write_text(TASK_FILE.format(name=name, kind=kind, arm=UR10, surface=surface_text,
                                     guess=[round(float(q), 4) for q in guess], gains=_flow(GAINS),
                                     pattern=_flow(dict(RASTER, center=list(center))), force=FORCE))
    task, config = load_task_file(path)
    config.duration = job_duration(task, config) + 0.5
    start = time.perf_counter()
    result = simulate(config)
    wall = time.perf_counter() - start
    scenario = result.scenario
    report = result.summary.path
    measured = measured_normal_force(result.log, scenario.controller_plant, scenario.robot,
                                     task.workpiece_surface(config)[0])
    length = job.path.length
    holds = []
    for h in HOLDS:
        ramp = [ForcePointConfig(0.0, RAMP[0]), ForcePointConfig(length, RAMP[1])]
        holds.append(dict(h=h, **eigenvalue_figures(linearize_continuous(with_path(config, hold_at=h,
                                                                                   force_by_arc_length=ramp)))))
    return {"route": "task file (UR10)", "surface": kind, "completed": report.completed,
            "segments": force_figures(result.log, report, measured), "report": report.as_dict(),
            "holds": holds, "wall_time": wall}


# -- the own-diagram route: the Panda ---------------------------------------------------------------------------

def own_station(arm, surface, spec, job, time_step, control_period, supervised):
    """A user's station: the Panda, the workpiece's geometry, the path job; (diagram, hybrid, loggers)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(time_step), builder)
    robot = arm.add_robot(plant)
    workpiece = add_surface_geometry(plant, surface, spec, name="workpiece")
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    chart = PoseChart()
    space = ConstraintSpace(surface.offset_constraint(chart, PAD), view_projection(chart, surface.default_view()))
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(arm.add_robot), gains=HybridGains(**GAINS),
                                   mode="position-force", control_period=control_period, path=job,
                                   supervision=SupervisionConfig(approach_speed=0.02, lift_height=0.01)
                                   if supervised else None,
                                   initial_phase=ContactPhase.APPROACH if supervised else None)
    loggers = add_loggers(builder, hybrid) if control_period is not None else None
    return builder.Build(), hybrid, loggers


def own_diagram_job(kind, spec, center, arm):
    """(figures) of the job on ``kind`` in a user's own diagram with the Panda."""
    surface = surface_of(spec, RigidTransform([0.5, 0.0, 0.15]))
    job = path_job(surface, PAD, path_settings(center))
    guess = arm.find_joint_guess(job.pose_at_depth(-0.005), seeds=8).positions
    diagram, hybrid, loggers = own_station(arm, surface, spec, job, 1e-3, 1e-3, True)
    context = diagram.CreateDefaultContext()
    solve_path_start(diagram, context, hybrid, guess)
    supervision = SupervisionConfig(approach_speed=0.02, lift_height=0.01)
    start = time.perf_counter()
    Simulator(diagram, context).AdvanceTo(job.duration(supervision, gap=0.005) + 0.5)
    wall = time.perf_counter() - start
    log = read_log(loggers, context)
    tau = design_time_constant(HybridGains(**GAINS).matrices(3, 3, ControlMode.POSITION_FORCE),
                               ControlMode.POSITION_FORCE, (1, 2))
    report = path_report(log, tau, job.path.duration, job.path.length)
    measured = measured_normal_force(log, hybrid.controller_plant, hybrid.robot, surface)
    holds = []
    for h in HOLDS:
        held = path_job(surface, PAD, path_settings(center, hold_at=h, ramp=RAMP, length=job.path.length))
        twin, twin_hybrid, _ = own_station(arm, surface, spec, held, 0.0, None, False)
        twin_context = twin.CreateDefaultContext()
        solve_path_start(twin, twin_context, twin_hybrid, guess)
        holds.append(dict(h=h, **eigenvalue_figures(linearize_at_contact(twin, twin_context, twin_hybrid))))
    return {"route": "own diagram (Panda)", "surface": kind, "completed": report.completed,
            "segments": force_figures(log, report, measured), "report": report.as_dict(), "holds": holds,
            "wall_time": wall}


def run(kinds=None, routes=("task file", "own diagram")):
    """Every job's figures (a list of dicts, docs/paths.json's ``surfaces``)."""
    results = []
    if "task file" in routes:
        ur10 = load_arm(SHARE / "robots/ur_description/urdf/ur10_robot.urdf", flange="tool0", collision="drop")
        with tempfile.TemporaryDirectory() as folder:
            for kind, (spec, center) in surfaces(0.7, 0.2).items():
                if kinds is None or kind in kinds:
                    results.append(task_file_job(kind, spec, center, folder, ur10))
                    print(results[-1]["route"], kind, summary_line(results[-1]), flush=True)
    if "own diagram" in routes:
        arm = panda_arm()
        for kind, (spec, center) in surfaces(0.5, 0.25).items():
            if kinds is None or kind in kinds:
                results.append(own_diagram_job(kind, spec, center, arm))
                print(results[-1]["route"], kind, summary_line(results[-1]), flush=True)
    return results


def summary_line(result):
    measured = max(s["measured_percent"] for s in result["segments"])
    reported = max(s["report_percent"] for s in result["segments"])
    worst = max(h["worst_percent"] for h in result["holds"])
    return (f"completed {result['completed']}, normal force from the wrench {measured:.3f} %, the report's "
            f"{reported:.3f} %, eigenvalues worst {worst:.2f} % (all matched: "
            f"{all(h['matched'] for h in result['holds'])}, unstable: {sum(h['unstable'] for h in result['holds'])})")


def _joined(values, digits):
    return " / ".join(f"{value:.{digits}f}" for value in values)


def table(results):
    """The page's table (markdown lines)."""
    rows = ["| route | surface | path | normal force from the wrench along the true normal: worst settled error "
            "per segment (%) | the report's (%) | mean normal force (N) | eigenvalues at h = 0, 0.25, 0.5, 0.75, 1: "
            "worst (%) | unstable | largest max \\|x-dot\\| |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        segments, holds = r["segments"], r["holds"]
        rows.append(
            f"| {r['route']} | {r['surface']} | {'completed' if r['completed'] else 'NOT completed'}, "
            f"{len(r['report']['segments'])} segments ({', '.join(str(s['segment']) for s in segments)} settled) | {_joined([s['measured_percent'] for s in segments], 3)} | "
            f"{_joined([s['report_percent'] for s in segments], 3)} | "
            f"{_joined([s['mean_normal_force'] for s in segments], 3)} | "
            f"{_joined([h['worst_percent'] for h in holds], 2)} | "
            f"{sum(h['unstable'] for h in holds)} | {max(h['residual'] for h in holds):.1e} |")
    return "\n".join(rows)


if __name__ == "__main__":
    print(table(run(kinds=sys.argv[1:] or None)))
