"""The flat disc's acceptance runs (docs/disc.md): a flat compliant disc that must lie flat, its orientation rows
force-controlled with zero moment, on surfaces the controller is given 8 deg and 5 mm off the real ones.

* a UR5e presses a 50 mm disc 20 N on a plane and on a cylinder (radius 10 cm), each modelled 8 deg and 5 mm
  off (``models/tasks/disc_plane.yaml``, ``disc_cylinder.yaml``), the orientation rows force-controlled and,
  the same jobs, held by position: the patch after five design time constants;
* the raster over the height-map part (``surface-polishing --option workpiece=bump``) with a 30 mm disc (and
  with the 50 mm one, and held), the patch and the force along the whole path;
* the closed loop linearized at those points (``path.hold_at``) against the design, and the force rows'
  damping K_fd that makes the moment rows' design exact on a compliant contact;
* a sweep of the model's tilt error, 0 to 15 deg, both ways (``docs/sweeps/disc_tilt.yaml``, local Dask);
* arms and surfaces the package does not ship: the UR10 of example-robot-data on a plate
  (``models/tasks/disc_ur10_plate.yaml``) and the Unitree Z1 on an ellipsoid of the user's, a station of
  the package's blocks in Python with the workpiece's geometry moved off the controller's surface.

Writes docs/disc.json, docs/disc.md and the figures docs/figures/disc_*.png.

    python docs/disc.py            # all, about 30 minutes on a quiet machine
    python docs/disc.py press sweep  # those parts again (press, raster, eigenvalues, sweep, other_arms), the rest kept
    python docs/disc.py --page     # the page again from docs/disc.json
"""

import dataclasses
import importlib.metadata
import json
import logging
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import sympy

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
from report_format import significant  # noqa: E402

from pydrake.geometry import Ellipsoid  # noqa: E402
from pydrake.math import RigidTransform, RotationMatrix  # noqa: E402
from pydrake.multibody.parsing import Parser  # noqa: E402
from pydrake.multibody.plant import AddMultibodyPlant  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402

from drake_hybrid.analysis.linearization import linearize_continuous  # noqa: E402
from drake_hybrid.control.gains import ControlMode, HybridGains  # noqa: E402
from drake_hybrid.control.phases import ContactPhase  # noqa: E402
from drake_hybrid.control.supervision import SupervisionConfig  # noqa: E402
from drake_hybrid.core.charts import PoseChart  # noqa: E402
from drake_hybrid.core.constraints import surface_constraint, with_force_rows  # noqa: E402
from drake_hybrid.core.projections import ConstraintSpace  # noqa: E402
from drake_hybrid.core.surface_moves import surface_error_pose  # noqa: E402
from drake_hybrid.core.surfaces import ViewPlane, view_projection  # noqa: E402
from drake_hybrid.experiments.simulation import simulate  # noqa: E402
from drake_hybrid.experiments.sweep import run_sweep  # noqa: E402
from drake_hybrid.experiments.sweep_results import read_results  # noqa: E402
from drake_hybrid.experiments.sweep_spec import load_spec  # noqa: E402
from drake_hybrid.station.arm import mount_tool, robot_plant  # noqa: E402
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config, only_tool_touches  # noqa: E402
from drake_hybrid.station.contact_start import solve_contact_start  # noqa: E402
from drake_hybrid.station.loggers import add_loggers, read_log  # noqa: E402
from drake_hybrid.station.loop import add_hybrid_controller  # noqa: E402
from drake_hybrid.station.sensing import add_contact_patch  # noqa: E402
from drake_hybrid.station.tools import ToolConfig  # noqa: E402
from drake_hybrid.station.workpieces import add_rigid_workpiece  # noqa: E402
from drake_hybrid.systems.contact_patch import PATCH_FIELDS  # noqa: E402
from drake_hybrid.systems.sources import Profile  # noqa: E402
from drake_hybrid.tasks.model_files import prepare_model  # noqa: E402
from drake_hybrid.tasks.path import job_duration, with_path  # noqa: E402
from drake_hybrid.tasks.registry import get_task  # noqa: E402
from drake_hybrid.tasks.task_file import load_task_file  # noqa: E402
from drake_hybrid.viz.figure_base import _pyplot  # noqa: E402
from drake_hybrid.viz.patch_plots import plot_pressure_snapshots, pressure_snapshots  # noqa: E402

logging.getLogger("drake").setLevel(logging.ERROR)
FIGURES = ROOT / "docs" / "figures"
TASKS = ROOT / "models" / "tasks"
COLUMN = {name: index for index, name in enumerate(PATCH_FIELDS)}
# The bump's raster: a 30 mm disc, the normal row at -10 and the moment rows at -1.5 1/s, K_fd matched to them.
BUMP_DISC = ToolConfig(kind="disc", radius=0.015)
BUMP_GAINS = dict(force_proportional=[0.5, 1.0, 1.0], force_integral=[15.0, 3.0, 3.0], force_damping=[10.0, 1.5, 1.5])


def held(config):
    """``config`` with the disc's orientation rows held by position (kinematic rows) instead."""
    return dataclasses.replace(config, tool=dataclasses.replace(config.tool, orientation="held"))


def _contact_normal_force(log, index):
    """|f| of the measured contact wrench (frictionless: along the real surface's normal), N."""
    return float(np.linalg.norm(np.asarray(log["wrench"])[index, 3:]))


def press(name, orientation):
    """A disc pressing on ``name`` (plane or cylinder, its task file) with its orientation rows ``orientation``."""
    task, config = load_task_file(TASKS / f"disc_{name}.yaml")
    if orientation == "held":
        config = held(config)
    result = simulate(config)
    log, summary = result.log, result.summary
    patch = summary.patch
    t = np.asarray(log["t"])
    settled = t >= patch.settled_from
    end = len(t) - 1
    command = float(log["desired_force"][end, 0])
    measured = [_contact_normal_force(log, i) for i in np.nonzero(settled)[0]]
    snapshots = pressure_snapshots(result.scenario, log, [summary.contact_time + 0.05, summary.contact_time + 0.4,
                                                         patch.settled_from, float(t[-1])])
    fig = plot_pressure_snapshots(snapshots, config.tool.radius,
                                  title=f"the disc on the {name}, orientation {orientation}")
    fig.savefig(FIGURES / f"disc_{name}_{orientation}_pressure.png", dpi=100)
    _pyplot().close(fig)
    return {"surface": name, "orientation": orientation, "status": summary.status,
            "contact_time": summary.contact_time, "settled_from": patch.settled_from,
            "cop_offset_mm": patch.final_cop_offset_mm, "max_cop_offset_mm_settled": patch.max_cop_offset_mm_settled,
            "tilt_deg": patch.final_tilt_deg, "max_tilt_deg_settled": patch.max_tilt_deg_settled,
            "area_fraction": patch.final_area_fraction, "peak_pressure_kpa": patch.final_peak_pressure_kpa,
            "mean_pressure_kpa": patch.final_mean_pressure_kpa,
            "force_row": float(log["force"][end, 0]), "command": command,
            "force_row_error_percent": 100 * float(np.max(np.abs(log["force"][settled, 0] - command))) / command,
            "contact_force": _contact_normal_force(log, end),
            "contact_force_error_percent": 100 * (max(measured, key=lambda f: abs(f - command)) - command) / command,
            "pressure_force": patch.final_normal_force, "history": _history(log)}


def _history(log, every=0.02):
    """The patch's figures every ``every`` s (for the page's figures)."""
    t = np.asarray(log["t"])
    keep = np.unique(np.searchsorted(t, np.arange(t[0], t[-1], every)))
    patch = np.asarray(log["patch"])[keep]
    return {"t": t[keep].tolist(), "cop_offset_mm": (1e3 * patch[:, COLUMN["cop_offset"]]).tolist(),
            "tilt_deg": np.degrees(patch[:, COLUMN["tilt"]]).tolist(),
            "area_fraction": patch[:, COLUMN["area_fraction"]].tolist(),
            "normal_force": patch[:, COLUMN["normal_force"]].tolist()}


def raster(label, tool, gains=BUMP_GAINS, orientation=None):
    """The surface-polishing raster over the bump with ``tool``: the path's and the patch's figures."""
    task = get_task("surface-polishing")
    config = task.default_config({"workpiece": "bump"})
    config.tool = dataclasses.replace(tool, orientation=orientation or tool.orientation)
    for key, value in gains.items():
        setattr(config.gains, key, value)
    config.duration = job_duration(task, config)
    result = simulate(config)
    summary, log = result.summary, result.log
    patch, path = summary.patch, summary.path
    on_path = (np.asarray(log["path_progress"])[:, 2] >= 0) & (np.asarray(log["path_done"])[:, 0] < 0.5)
    command = np.asarray(log["desired_force"])[on_path, 0]
    force_error = 100 * float(np.max(np.abs(np.asarray(log["force"])[on_path, 0] - command) / command))
    contact = np.array([_contact_normal_force(log, i) for i in np.nonzero(on_path)[0]])
    return {"label": label, "radius": tool.radius, "orientation": config.tool.orientation_rows,
            "status": summary.status, "completed": path.completed,
            "path_max_cop_offset_mm": patch.path_max_cop_offset_mm, "path_max_tilt_deg": patch.path_max_tilt_deg,
            "path_min_area_fraction": patch.path_min_area_fraction,
            "path_max_force_row_error_percent": force_error,
            "path_max_contact_force_error_percent": 100 * float(np.max(np.abs(contact - command) / command)),
            "settled_force_error_percent": path.max_force_error_percent,
            "settled_path_error_along_surface_mm": path.max_path_error_along_surface_mm,
            "time_off_surface_s": path.time_off_surface_s, "contact_losses": path.contact_losses,
            "history": _history(log)}


def _match(lin):
    match = lin.match
    return {"matched": bool(match.matched), "worst_percent": 100 * float(np.max(match.relative_error)),
            "designed": [float(v.real) for v in match.predicted],
            "measured": [[float(v.real), float(v.imag)] for v in match.partner],
            "errors_percent": [100 * float(e) for e in match.relative_error],
            "unstable": [[float(v.real), float(v.imag)] for v in match.unstable_extra],
            "slowest_extra": [[float(v.real), float(v.imag)] for v in
                              sorted(match.extra, key=lambda v: -v.real)[:2]]}


def eigenvalues():
    """The continuous loop at the points of the jobs (the model exact: at an equilibrium, the disc flat) against
    the design; and the force rows' damping K_fd: none (the paper's), matched (K_fi / (1 + K_fp)), heavier."""
    rows = []
    for name in ("plane", "cylinder"):
        _, config = load_task_file(TASKS / f"disc_{name}.yaml")
        config = dataclasses.replace(config, model_error=dataclasses.replace(
            config.model_error, workpiece_tilt=0.0, workpiece_shift=[0.0, 0.0, 0.0]))
        rows.append({"job": name, "point": "hold_at 0", "force_damping": "10, 10, 10",
                     **_match(linearize_continuous(config))})
    task = get_task("surface-polishing")
    base = task.default_config({"workpiece": "bump"})
    base.tool = BUMP_DISC
    for key, value in BUMP_GAINS.items():
        setattr(base.gains, key, value)
    for hold in (0.0, 0.25, 0.5, 0.75, 1.0):
        rows.append({"job": "bump", "point": f"hold_at {hold:g}", "force_damping": "10, 1.5, 1.5",
                     **_match(linearize_continuous(with_path(base, hold_at=hold)))})
    for damping, label in (([0.0, 0.0, 0.0], "0, 0, 0 (the paper's)"), ([10.0, 10.0, 10.0], "10, 10, 10")):
        config = with_path(base, hold_at=1.0)
        config.gains = dataclasses.replace(config.gains, force_damping=damping)
        rows.append({"job": "bump", "point": "hold_at 1", "force_damping": label,
                     **_match(linearize_continuous(config))})
    held_config = with_path(base, hold_at=0.5)
    held_config.tool = dataclasses.replace(BUMP_DISC, orientation="held")
    rows.append({"job": "bump, orientation held", "point": "hold_at 0.5", "force_damping": "10, 1.5, 1.5",
                 **_match(linearize_continuous(held_config))})
    ball = with_path(task.default_config({"workpiece": "bump"}), hold_at=0.5)
    rows.append({"job": "bump, the ball pad", "point": "hold_at 0.5", "force_damping": "0",
                 **_match(linearize_continuous(ball))})
    return rows


SWEEP_COLUMNS = ("model_error.workpiece_tilt", "tool.orientation", "patch_cop_offset_mm", "patch_tilt_deg",
                 "patch_area_fraction", "patch_normal_force", "path_contact_losses", "path_time_off_surface",
                 "steady_force_error_percent", "error")


def tilt_sweep():
    """The model's tilt error swept, 0 to 15 deg, with the orientation force-controlled and held (a local Dask
    cluster of two workers): the patch at the end of each run."""
    load_task_file(TASKS / "disc_plane.yaml")                    # registers disc-plane
    with tempfile.TemporaryDirectory() as folder:
        run_sweep("disc-plane", load_spec(path=ROOT / "docs" / "sweeps" / "disc_tilt.yaml"), folder, workers=2,
                  progress=False)
        rows = read_results(Path(folder) / "results.csv")
    return sorted(({key: row.get(key) for key in SWEEP_COLUMNS} for row in rows),
                  key=lambda row: (row["tool.orientation"], float(row["model_error.workpiece_tilt"])))


# -- the Unitree Z1 on an ellipsoid of the user's: the package's blocks in a station of one's own ------------
Z1_SHARE = Path(importlib.metadata.distribution("example-robot-data").locate_file(
    "cmeel.prefix/share/example-robot-data"))
CENTER, AXES = np.array([0.26, 0.0, 0.253]), np.array([0.12, 0.08, 0.06])
Z1_GUESS = [0.0, 1.5, -1.5, 1.2, 0.0, 0.0]


def z1_on_an_ellipsoid(error_tilt=5.0, error_shift=-0.003, duration=7.0, slide_from=4.0):
    """A Z1 (example-robot-data, its gripper removed) with a 30 mm disc pressing 8 N near the top of an ellipsoid
    whose geometry is ``error_tilt`` deg and ``error_shift`` m off the controller's (the pose error applied to
    the workpiece's geometry only), then sliding 1 cm/s along x from ``slide_from``: the patch before the slide
    and at the end."""
    z1 = prepare_model(Z1_SHARE / "robots/z1_description/urdf/z1.urdf")
    tool = ToolConfig(kind="disc", radius=0.015)

    def add_robot(plant):
        arm = Parser(plant).AddModels(z1.model)[0]
        return mount_tool(plant, arm, "link06", RigidTransform(RotationMatrix.MakeYRotation(np.pi / 2), [0.02, 0, 0]),
                          gripper_joints=["jointGripper"], gripper="remove", tool=tool)

    chart = PoseChart()
    f = lambda p: AXES[2] * (sympy.sqrt(sum(((p[i] - CENTER[i]) / AXES[i]) ** 2 for i in range(3))) - 1)
    constraint = with_force_rows(surface_constraint(chart, f, name="ellipsoid"))     # the moments force-controlled
    space = ConstraintSpace(constraint, view_projection(chart, ViewPlane.make(CENTER)))
    dx = -0.03                        # the start, 3 cm from the top toward the arm (the Z1 reaches it)
    top = CENTER + [dx, 0.0, AXES[2] * math.sqrt(1 - (dx / AXES[0]) ** 2)]
    normal = (top - CENTER) / AXES ** 2
    normal /= np.linalg.norm(normal)
    X_real_model = surface_error_pose(error_tilt, [0.0, 1.0, 0.0], top, [0.0, 0.0, error_shift])
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(1e-3), builder)
    robot = add_robot(plant)
    workpiece = add_rigid_workpiece(plant, Ellipsoid(*AXES), X_real_model @ RigidTransform(CENTER))
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    gains = HybridGains(velocity=[16.0], position=[48.0], force_proportional=[0.5, 1.0, 1.0],
                        force_integral=[15.0, 3.0, 3.0], force_damping=[10.0, 10.0, 10.0])
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=gains,
                                   mode=ControlMode.POSITION_FORCE, control_period=1e-3,
                                   desired_velocity=Profile(kind="smooth_step", value=[0.0, 0.0, 0.0],
                                                            final_value=[0.0, 0.01, 0.0], start_time=slide_from,
                                                            duration=0.5),
                                   desired_force=Profile(value=[8.0, 0.0, 0.0]),
                                   supervision=SupervisionConfig(enabled=True, approach_speed=0.02),
                                   initial_phase=ContactPhase.APPROACH, normal_force_axis="tool")
    hybrid.patch = add_contact_patch(builder, plant, robot)
    loggers = add_loggers(builder, hybrid)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    # At rest on the model's top, the tool down, pressing nothing: the real top is 3 mm below it, and the
    # supervisor's guarded approach lands the disc.
    start = RigidTransform(RotationMatrix.MakeYRotation(np.pi - math.asin(-normal[0])), top)
    solve_contact_start(diagram, context, hybrid, start, Z1_GUESS, desired_force=[0.0, 0.0, 0.0])
    Simulator(diagram, context).AdvanceTo(duration)
    log = read_log(loggers, context)
    patch, t = np.asarray(log["patch"]), np.asarray(log["t"])
    pressing = int(np.searchsorted(t, slide_from)) - 1
    sliding = t >= slide_from + 0.5
    end = len(t) - 1
    return {"arm": "Unitree Z1 (example-robot-data)", "surface": "ellipsoid 0.12 x 0.08 x 0.06 m (the user's)",
            "error": f"{error_tilt:g} deg, {1e3 * abs(error_shift):g} mm", "disc_radius": tool.radius,
            "cop_offset_mm": 1e3 * float(patch[pressing, COLUMN["cop_offset"]]),
            "tilt_deg": math.degrees(float(patch[pressing, COLUMN["tilt"]])),
            "area_fraction": float(patch[pressing, COLUMN["area_fraction"]]),
            "force_row": float(log["force"][pressing, 0]), "command": 8.0,
            "contact_force": float(np.linalg.norm(np.asarray(log["wrench"])[pressing, 3:])),
            "sliding_max_cop_offset_mm": 1e3 * float(np.max(patch[sliding, COLUMN["cop_offset"]])),
            "sliding_max_tilt_deg": math.degrees(float(np.max(patch[sliding, COLUMN["tilt"]]))),
            "sliding_max_force_row_error_percent": 100 * float(np.max(np.abs(log["force"][sliding, 0] - 8.0))) / 8.0,
            "phase_at_end": int(log["contact_phase"][end, 0])}


def ur10():
    """The UR10 of example-robot-data pressing its disc on a plate modelled 8 deg and 5 mm off."""
    row = press("ur10_plate", "force")
    row["arm"] = "UR10 (example-robot-data, the arm loader)"
    return row


PARTS = {
    "press": lambda: [press(name, orientation) for name in ("plane", "cylinder") for orientation in ("force", "held")],
    "raster": lambda: [raster("30 mm disc, moments", BUMP_DISC), raster("30 mm disc, held", BUMP_DISC, orientation="held"),
                       raster("50 mm disc, moments", ToolConfig(kind="disc"))],
    "eigenvalues": lambda: eigenvalues(),
    "sweep": lambda: tilt_sweep(),
    "other_arms": lambda: [ur10(), z1_on_an_ellipsoid()],
}


def run(parts=tuple(PARTS)):
    """The parts ``parts`` measured again, the others kept from docs/disc.json; each part written to it (and
    the page) as soon as it is measured."""
    path = ROOT / "docs" / "disc.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for part in parts:
        results[part] = PARTS[part]()
        if all(name in results for name in PARTS):
            write(results)
    return results


def _stopped(error):
    """A sweep point's error on the page: its first line up to the configuration it names, as code."""
    if not error:
        return ""
    return "`" + error.splitlines()[0].split(" at {")[0].split(" (rank margin")[0].replace("`", "'") + "`"


def _percent(fraction):
    return None if fraction is None else 100 * fraction


def _fmt(value, digits=3):
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{significant(value, digits):g}" if isinstance(value, float) else str(value)


def figures(results):
    """The patch over time (plane and cylinder, moments against held) and the tilt sweep."""
    plt = _pyplot()
    fig, axes = plt.subplots(3, 2, figsize=(10, 7.5), sharex=True)
    for column, name in enumerate(("plane", "cylinder")):
        for row in results["press"]:
            if row["surface"] != name:
                continue
            history = row["history"]
            style = "-" if row["orientation"] == "force" else "--"
            label = "orientation force-controlled" if row["orientation"] == "force" else "orientation held"
            axes[0][column].plot(history["t"], history["cop_offset_mm"], style, label=label)
            axes[1][column].plot(history["t"], history["tilt_deg"], style)
            axes[2][column].plot(history["t"], 100 * np.asarray(history["area_fraction"]), style)
        axes[0][column].set_title(f"{name}, modelled 8 deg and 5 mm off")
        axes[2][column].set_xlabel("t (s)")
    axes[0][0].set_ylabel("centre of pressure\nfrom the axis (mm)")
    axes[1][0].set_ylabel("tilt against the\nreal surface (deg)")
    axes[2][0].set_ylabel("face in contact (%)")
    axes[0][0].legend(fontsize=8)
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(FIGURES / "disc_press.png", dpi=100)
    plt.close(fig)
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4))
    for orientation, style in (("force", "o-"), ("held", "s--")):
        rows = [r for r in results["sweep"] if r["tool.orientation"] == orientation]
        tilt = [float(r["model_error.workpiece_tilt"]) for r in rows]
        for ax, key, scale in ((axes[0], "patch_cop_offset_mm", 1.0), (axes[1], "patch_tilt_deg", 1.0),
                               (axes[2], "patch_area_fraction", 100.0)):
            values = [scale * float(r[key]) if r[key] not in (None, "") else np.nan for r in rows]
            ax.plot(tilt, values, style, label=f"orientation {orientation}")
    for ax, label in zip(axes, ("centre of pressure from the axis (mm)", "tilt against the real surface (deg)",
                                "face in contact (%)")):
        ax.set_xlabel("the model's tilt error (deg)")
        ax.set_title(label, fontsize=9)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIGURES / "disc_tilt_sweep.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 3.2))
    for row in results["raster"]:
        ax.plot(row["history"]["t"], row["history"]["cop_offset_mm"], lw=1.0, label=row["label"])
    ax.axhline(2.0, color="0.4", ls=":", lw=1.0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("centre of pressure\nfrom the axis (mm)")
    ax.set_title("the raster over the bump (10 N, 5 cm/s)", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(FIGURES / "disc_bump.png", dpi=100)
    plt.close(fig)


def page(results):
    lines = [PAGE_HEAD]
    lines += ["| surface | orientation | centre of pressure from the axis (mm): final / settled max | tilt against the "
              "real surface (deg): final / settled max | face in contact (%) | pressure: peak / mean (kPa) | force "
              "row F_1 (N): final / settled error (%) | contact force along the real normal (N): final / settled "
              "error (%) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in results["press"]:
        lines.append(f"| {r['surface']} | {r['orientation']} | {_fmt(r['cop_offset_mm'])} / "
                     f"{_fmt(r['max_cop_offset_mm_settled'])} | {_fmt(r['tilt_deg'])} / "
                     f"{_fmt(r['max_tilt_deg_settled'])} | {_fmt(_percent(r['area_fraction']))} | "
                     f"{_fmt(r['peak_pressure_kpa'])} / {_fmt(r['mean_pressure_kpa'])} | {_fmt(r['force_row'], 5)} / "
                     f"{_fmt(r['force_row_error_percent'])} | {_fmt(r['contact_force'], 4)} / "
                     f"{_fmt(r['contact_force_error_percent'])} |")
    lines += ["", PAGE_PRESS, "", "![The patch over time](figures/disc_press.png)", "",
              "![The pressure over the disc on the plane, moments](figures/disc_plane_force_pressure.png)",
              "![The pressure over the disc on the plane, held](figures/disc_plane_held_pressure.png)",
              "![The pressure over the disc on the cylinder, moments](figures/disc_cylinder_force_pressure.png)", "",
              PAGE_RASTER, "",
              "| disc | orientation | completed | centre of pressure along the path, max (mm) | tilt along the path, max "
              "(deg) | face in contact along the path, min (%) | force row along the path, max error (%) | contact "
              "force along the path, max error (%) | settled: force error (%) / path error along the surface (mm) "
              "| off the surface (s) |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["raster"]:
        lines.append(f"| {1e3 * 2 * r['radius']:.0f} mm | {r['orientation']} | {r['completed']} | "
                     f"{_fmt(r['path_max_cop_offset_mm'])} | {_fmt(r['path_max_tilt_deg'])} | "
                     f"{_fmt(100 * r['path_min_area_fraction'] if r['path_min_area_fraction'] is not None else None)} | "
                     f"{_fmt(r['path_max_force_row_error_percent'])} | {_fmt(r['path_max_contact_force_error_percent'])}"
                     f" | {_fmt(r['settled_force_error_percent'])} / {_fmt(r['settled_path_error_along_surface_mm'])} "
                     f"| {_fmt(r['time_off_surface_s'])} |")
    lines += ["", "![The centre of pressure along the raster](figures/disc_bump.png)", "", PAGE_EIGEN, "",
              "| job | point | K_fd (1/s) | every designed eigenvalue within 5 % | worst (%) | the moment rows' "
              "(-1.5 1/s): errors (%) | unstable | the slowest other modes |", "|---|---|---|---|---|---|---|---|"]
    for r in results["eigenvalues"]:
        moments = [e for d, e in zip(r["designed"], r["errors_percent"]) if abs(d + 1.5) < 1e-9]
        others = ", ".join(f"{re:.2f}{im:+.2f}j" for re, im in r["slowest_extra"])
        unstable = ", ".join(f"{re:.2f}{im:+.2f}j" for re, im in r["unstable"]) or "none"
        lines.append(f"| {r['job']} | {r['point']} | {r['force_damping']} | {r['matched']} | "
                     f"{_fmt(r['worst_percent'])} | {', '.join(_fmt(e) for e in moments) or 'held'} | {unstable} | "
                     f"{others} |")
    lines += ["", PAGE_SWEEP, "",
              "| the model's tilt error (deg) | orientation | centre of pressure from the axis (mm) | tilt against "
              "the real surface (deg) | face in contact (%) | pressure's normal force (N) | contact losses | "
              "off the surface (s) | error |", "|---|---|---|---|---|---|---|---|---|"]
    for r in results["sweep"]:
        area = r["patch_area_fraction"]
        lines.append(f"| {float(r['model_error.workpiece_tilt']):g} | {r['tool.orientation']} | "
                     f"{_fmt(_num(r['patch_cop_offset_mm']))} | {_fmt(_num(r['patch_tilt_deg']))} | "
                     f"{_fmt(100 * _num(area) if _num(area) is not None else None)} | "
                     f"{_fmt(_num(r['patch_normal_force']))} | {_count(r['path_contact_losses'])} | "
                     f"{_fmt(_num(r['path_time_off_surface']))} | {_stopped(r['error'])} |")
    lines += ["", "![The tilt sweep](figures/disc_tilt_sweep.png)", "", PAGE_OTHERS, "",
              "| arm | surface | the model off the real one | disc | centre of pressure from the axis (mm) | tilt "
              "against the real surface (deg) | face in contact (%) | force row F_1 (N) | contact force (N) | sliding: "
              "centre of pressure / tilt / force row, max |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results["other_arms"]:
        surface = r.get("surface", "plate (a plane), 8 deg and 5 mm off" if "arm" in r else "")
        error = r.get("error", "8 deg, 5 mm")
        lines.append(f"| {r['arm']} | {surface} | {error} | {1e3 * 2 * r.get('disc_radius', 0.03):.0f} mm | "
                     f"{_fmt(r['cop_offset_mm'])} | {_fmt(r['tilt_deg'])} | {_fmt(_percent(r['area_fraction']))} | "
                     f"{_fmt(r['force_row'], 5)} (command {_fmt(r['command'])}) | {_fmt(r['contact_force'], 4)} | "
                     + (f"{_fmt(r['sliding_max_cop_offset_mm'])} mm / {_fmt(r['sliding_max_tilt_deg'])} deg / "
                        f"{_fmt(r['sliding_max_force_row_error_percent'])} % |" if "sliding_max_cop_offset_mm" in r
                        else "(pressing only) |"))
    lines += ["", PAGE_TAIL]
    return "\n".join(lines) + "\n"


def _count(value):
    return "n/a" if _num(value) is None else f"{int(_num(value))}"


def _num(value):
    if value in (None, ""):
        return None
    value = float(value)
    return value if math.isfinite(value) else None


PAGE_HEAD = """# A flat tool that presses evenly: the disc, its moment rows and its contact patch

Generated by `python docs/disc.py` (the acceptance runs of the flat disc). A ball pad does not care how it is
turned; a flat disc does: tilted a few degrees it digs in with its rim. With the constraint's orientation rows
force-controlled (`tool.orientation: force`, the disc's default; `core.constraints.with_force_rows`) and zero
moment commanded, the law turns the disc until the hydroelastic pressure is centred under its axis, wherever the
real surface is; held by position (`tool.orientation: held`, the rows kinematic) the disc follows the model's
normal. The patch is measured from Drake's hydroelastic contact results every 10 ms
(`systems.contact_patch`, the log's `patch`, the summary's `patch`): the centre of pressure's distance from the
disc's axis, the share of the face in contact, the peak and mean pressure, and the disc's tilt against the real
surface's normal under its centre.

## The disc on a plane and on a cylinder, each modelled 8 deg and 5 mm off

A UR5e presses a disc 50 mm across (10 mm thick, hydroelastic modulus 0.3 MPa) with 20 N on a plane and on a
cylinder of radius 10 cm lying on its side; the controller is given each surface turned 8 deg (about
[1, 1, 0], through the path's first point) and moved 5 mm (`model_error.workpiece_*`: the geometry Drake
simulates is the real one; the controller's constraint, view and path are laid on the model). The guarded
approach lands the disc from 5 mm above the model's point; the job then holds that point (`path.hold_at: 0`).
Position-force mode, the velocity rows at -10 and -20, the normal force row at -10 (K_fp = 0.5, K_fi = 15), the
moment rows at -1.5 1/s (K_fp = 1, K_fi = 3), the force rows' damping K_fd = 10 1/s (below). Five design time
constants are 3.3 s; "settled" is from the first contact + 3.3 s to the end (6 s). "Force row F_1" is what the
law controls: with the orientation force-controlled the force along the disc's axis (`tool.normal_force: tool`,
the disc's default, below), held by position the force along the model's normal in E's dual basis; "contact
force" is the measured contact force, which, frictionless, lies along the real normal.
"""

PAGE_PRESS = """With the moment rows force-controlled the disc lies flat on the real surface wherever the model puts it: the
centre of pressure ends within micrometres of the axis and the tilt within hundredths of a degree; on the plane
the whole face presses (the share below 100 % is the disc mesh's rim, where its pressure field falls to zero),
on the cylinder a strip along its axis (a flat disc on a convex surface). Held by position, the disc stays
8 deg off the plane's real normal: it digs in with its rim, a quarter of its face in contact, the pressure's
centre 18 mm off its axis.

**The normal force.** With the orientation force-controlled the normal row reads the force along the disc's own
axis (`tool.normal_force: tool`, the disc's default; `control.normal_force`): the measured wrench is changed along
the model's normal so that the row's reading in E's dual basis is the force along the axis. Once the disc lies flat
on the real surface its axis is the real normal, so the contact force Drake applies is the command: on the plane
20.00 N, -0.065 % at most once settled (the row's own error; before this reading the row held the force along the
model's normal, and the disc pressed 1 / cos 8 deg = +0.98 % too hard, +1.04 % measured), on the cylinder 20.00 N
to the row's accuracy. Held by position, the disc's row is the model's normal (`normal_force: model`, a held
disc's default: its axis is the model's normal anyway), and its contact force, along the real normal, reads
+0.98 % on the plane (1 / cos 8 deg). (The pressure integrated over the patch, `patch`'s normal force,
reads 0.35 % above the contact force Drake applies on the plane: SAP's discrete contact is not the pressure
field's integral exactly.)"""

PAGE_RASTER = """## A raster over the height-map part

The surface-polishing raster over the bump (`surface-polishing --option workpiece=bump`: a Gaussian bump 3 cm
high, sigma 3 cm; 10 cm x 10 cm at 5 cm/s and 10 N, 11 segments, approach to lift-off) with a disc, the model
exact. The bump's top is convex with a 3 cm radius and its flanks concave: a flat disc bridges the curvature,
so only part of its face touches. The 30 mm disc keeps its centre of pressure within the 2 mm target along the
whole path (1.08 mm), its force row (the force along its axis) within 2 % (1.78 %) and the contact force Drake
applies within 2 % too (1.75 %; read along the model's normal in E's dual basis, as before the axis reading,
it strayed to 2.74 %: on the flanks E_p's rows are not orthogonal to the normal, and the row then mixes in a
share of the tangential force, `control.normal_force`). The ball pad on the same raster: 0.24 %
(docs/paths.md). The 50 mm disc, wider than the bump's curvature allows, does not (its rim rests across the
flanks' hollows, and the zero-moment orientation changes faster than its moment loop follows at 5 cm/s). The
tilt here is against the surface's normal under the disc's centre, which a disc resting on its rim across a
curved surface does not share: no target."""

PAGE_EIGEN = """## The linearized loop at those points

The continuous closed loop (`linearize_continuous`, the plant continuous, the wrench low-passed at 200 Hz) at
the points of the jobs, the model exact (an equilibrium: the disc flat, its start turned until its moments read
zero, `tasks.pressing.balanced_pressing_positions`), against the design.

**Why K_fd.** The paper's force law commands no acceleration along the force rows (a_f = 0 in (3.0-11)), which
rigid contact enforces. On a compliant contact of stiffness k and damping c a force row of inertia Lambda closes
as Lambda s^3 + (Lambda K_fd + (1 + K_fp) c) s^2 + ((1 + K_fp) k + K_fi c) s + K_fi k = 0. With K_fd = 0 the sum of
its roots is -(1 + K_fp) c / Lambda while the slow root stays near -K_fi / (1 + K_fp): its fast pair grows unless
the contact dissipates (1 + K_fp) c > Lambda K_fi / (1 + K_fp). A moment row's Lambda is the arm's rotational
inertia about the tool's axes (0.01 to 0.1 kg m^2 on the UR5e), its c the pressure's lever squared: the disc's
moment rows are unstable without K_fd (the table's first bump row). `HybridGains.force_damping` adds
a_f = -K_fd C-dot on the force rows in contact: nothing changes under rigid contact (C-dot = 0 there), and with
**K_fd = K_fi / (1 + K_fp)** the cubic factors exactly into (s + K_fi / (1 + K_fp)) (Lambda s^2 + (1 + K_fp) c s +
(1 + K_fp) k): the designed eigenvalue, whatever the contact's stiffness and the arm's inertia, and the contact's
own mode, damped by the contact. A heavier K_fd damps that mode more and moves the slow root by about
s_0 Lambda s_0 (s_0 + K_fd) / ((1 + K_fp) k): little where the contact is stiff in rotation (a face on a plane,
along a cylinder), much where it is soft (a flat disc rocking on the bump's 3 cm top, k about F R = 0.3 N m/rad).
The landing on a surface 8 deg off (the rim first, the moment saturated at F r until the face meets the plane)
needs the heavier damping: with the matched K_fd = 1.5 1/s the disc rocked off the plane; with 10 1/s it lands
(the first table). The raster, on an exact model, runs with the matched one. On the bump's flank at h = 0.5
one motion row's -20 root reads -21.05 (5.25 %, the only miss): the disc's rocking mode there (-0.16 +- 9.7j,
lightly damped by the contact alone) couples into it; the moment rows' own roots are within 0.06 %. The normal
row reads the force along the disc's axis (above); at these equilibria that changes the designed roots by at most
0.03 points against the model's reading (second order: the force lies along the axis), and a start turned off
the model's normal (the flanks) holds the contact's own force with its force integral
(`tasks.pressing.held_force_integral`), so that it is the law's equilibrium."""

PAGE_SWEEP = """## The model's tilt error swept

`docs/sweeps/disc_tilt.yaml` on the plane job (local Dask, two workers): the model turned 0 to 15 deg (5 mm off
too), the orientation force-controlled and held; the patch at the end of each 6 s run. With the moments
force-controlled, alignment holds up to 9 deg of model error (the centre of pressure within 2 um of the axis, the
whole face pressing, no contact loss). At 12 and 15 deg it does not: the disc lands on its rim, the moment rows
turn it past the face and over (at 12 deg its axis ends 82 deg from the normal), and the run stops on the
constraint's rank check, reported as an error with its log kept; no run lost contact before that. Held by
position, the disc keeps the model's tilt exactly (its tilt against the real surface is the model's error) and
the face in contact falls from 99.8 % to 18 % at 15 deg, the pressure's centre up to 19 mm off the axis."""

PAGE_OTHERS = """## Arms and surfaces the package does not ship

The UR10 of example-robot-data (the arm loader, a task file: `models/tasks/disc_ur10_plate.yaml`) presses a
60 mm disc 15 N on a plate modelled 8 deg and 5 mm off; the Unitree Z1 of example-robot-data (its gripper
removed) presses a 30 mm disc 8 N near the top of an ellipsoid of the user's (`surface_constraint` of its sympy
f, `with_force_rows`), in a station of the package's blocks in Python, the ellipsoid's geometry turned 5 deg and
moved 3 mm from the controller's (`surface_error_pose` on the workpiece's pose only): the patch at t = 4 s, then
while it slides 1 cm/s along x (from t = 4.5 s to 7 s, the last column)."""

PAGE_TAIL = """How to use the disc: [a task file's or a config's `tool:`](task_files.md), `mount_tool(..., tool=ToolConfig(kind="disc"))`
and `add_contact_patch` in your own station ([your own diagram](howto/own_diagram.md)), and tutorial 9's last
section."""


def write(results):
    (ROOT / "docs" / "disc.json").write_text(json.dumps(results, indent=1))
    (ROOT / "docs" / "disc.md").write_text(page(results))


if __name__ == "__main__":
    if "--page" in sys.argv:
        results = json.loads((ROOT / "docs" / "disc.json").read_text())
    else:
        chosen = [name for name in sys.argv[1:] if name in PARTS]
        unknown = [name for name in sys.argv[1:] if name not in PARTS and name.startswith("-") is False]
        if unknown:
            raise SystemExit(f"unknown parts {unknown}; choose from {sorted(PARTS)}")
        results = run(tuple(chosen) or tuple(PARTS))
        figures(results)
    write(results)
