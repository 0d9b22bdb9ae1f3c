"""A flat tool's contact patch drawn: the pressure over the disc at chosen instants, and the patch's figures
over the run (centre of pressure, tilt, area in contact, normal force).

``pressure_snapshots(scenario, log, times)`` puts the simulated plant, in a context of its own, at the logged
joint positions of each instant and integrates SceneGraph's hydroelastic contact surfaces there
(``systems.contact_patch.pressure_samples``: the workpiece is fixed, so the positions fix the patch);
``plot_pressure_snapshots`` draws them in the tool's frame (the face seen from the workpiece, its outline,
the axis and the centre of pressure); ``plot_patch_history`` the ``patch`` log. ``save_patch_plots`` writes
both for ``viz.outputs.write_run`` (patch_pressure.png, patch.png).
"""

import math
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence

import numpy as np

from pydrake.geometry import HydroelasticContactRepresentation

from drake_hybrid.core.hints import Array
from drake_hybrid.systems.contact_patch import PATCH_FIELDS, pressure_samples
from drake_hybrid.viz.figure_base import _pyplot

_COLUMN = {name: index for index, name in enumerate(PATCH_FIELDS)}


def pressure_snapshots(scenario: Any, log: Mapping[str, Array], times: Sequence[float]) -> List[Dict[str, Any]]:
    """The pressure over the pad at each of ``times`` (s; the nearest logged sample): {"t", "points" (N x 3 in
    the tool's frame, m), "pressure" (Pa), "area" (m^2)} per instant, from the scenario's plant at the logged
    positions ``log["q"]`` (a task run's log, ``experiments.simulation``)."""
    plant, robot = scenario.plant, scenario.robot
    context = scenario.diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    frame = plant.GetFrameByName(robot.end_effector_frame)
    t = np.asarray(log["t"])
    snapshots = []
    for time in times:
        index = int(np.clip(np.searchsorted(t, time), 0, len(t) - 1))
        plant.SetPositions(plant_context, robot.arm, np.asarray(log["q"][index]))
        query = plant.get_geometry_query_input_port().Eval(plant_context)
        surfaces = query.ComputeContactSurfaces(HydroelasticContactRepresentation.kPolygon)
        X_WT = frame.CalcPoseInWorld(plant_context)
        samples = pressure_samples(surfaces, robot.pad_geometries, X_WT)
        snapshots.append({"t": float(t[index]), **samples})
    return snapshots


def plot_pressure_snapshots(snapshots: Sequence[Mapping[str, Any]], face_radius: Optional[float] = None,
                            title: str = "pressure over the disc"):
    """One panel per snapshot (``pressure_snapshots``): each face of the patch at its centroid, coloured by its
    pressure (kPa, one scale for all), in the tool's frame seen from the workpiece (x, y in mm); the face's
    outline (``face_radius``, m), its centre (the tool's axis, +) and the centre of pressure (x). Returns the
    figure."""
    plt = _pyplot()
    count = max(1, len(snapshots))
    fig, axes = plt.subplots(1, count, figsize=(3.2 * count + 0.8, 3.6), squeeze=False)
    top = max([float(np.max(s["pressure"], initial=0.0)) for s in snapshots] + [1.0]) / 1e3
    image = None
    extent = 1e3 * (face_radius or 0.025) * 1.15
    for ax, snapshot in zip(axes[0], snapshots):
        points, pressure, area = snapshot["points"], np.asarray(snapshot["pressure"]), np.asarray(snapshot["area"])
        ax.set_aspect("equal")
        if face_radius:
            ax.add_patch(plt.Circle((0.0, 0.0), 1e3 * face_radius, fill=False, color="0.4", lw=1.0))
        ax.plot([0.0], [0.0], "+", color="k", ms=9)
        if len(pressure):
            size = np.clip(4e6 * area, 2.0, 60.0)
            image = ax.scatter(1e3 * points[:, 0], 1e3 * points[:, 1], c=pressure / 1e3, s=size, cmap="viridis",
                               vmin=0.0, vmax=top, marker="s", linewidths=0)
            weights = np.clip(pressure, 0, None) * area
            if weights.sum() > 0:
                cop = (weights[:, None] * points).sum(axis=0) / weights.sum()
                ax.plot([1e3 * cop[0]], [1e3 * cop[1]], "x", color="r", ms=9, mew=2)
            in_contact = f"{1e6 * area.sum():.0f} mm^2"
        else:
            in_contact = "no contact"
        ax.set_xlim(-extent, extent)
        ax.set_ylim(-extent, extent)
        ax.set_title(f"t = {snapshot['t']:.2f} s\n{in_contact}", fontsize=9)
        ax.set_xlabel("tool x (mm)")
    axes[0][0].set_ylabel("tool y (mm)")
    if image is not None:
        fig.colorbar(image, ax=list(axes[0]), label="pressure (kPa)", shrink=0.85)
    fig.suptitle(f"{title} (+: the tool's axis, x: the centre of pressure)", fontsize=10)
    return fig


def plot_patch_history(log: Mapping[str, Array], command: Optional[float] = None):
    """The ``patch`` log over time: the centre of pressure's distance from the axis (mm), the tilt against the
    real surface (deg), the share of the face in contact (%), the normal force (N, with ``command``). Returns the
    figure."""
    plt = _pyplot()
    t, patch = np.asarray(log["t"]), np.asarray(log["patch"])
    fig, axes = plt.subplots(4, 1, figsize=(7.5, 7.5), sharex=True)
    rows = (("cop_offset", 1e3, "centre of pressure\nfrom the axis (mm)"),
            ("tilt", 180 / math.pi, "tilt against the\nreal surface (deg)"),
            ("area_fraction", 100.0, "face in contact (%)"),
            ("normal_force", 1.0, "normal force (N)"))
    for ax, (name, scale, label) in zip(axes, rows):
        ax.plot(t, scale * patch[:, _COLUMN[name]], lw=1.2)
        ax.set_ylabel(label, fontsize=9)
        ax.grid(True, alpha=0.3)
    if command is not None:
        axes[3].axhline(command, color="0.4", ls="--", lw=1.0, label="command")
        axes[3].legend(fontsize=8)
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    return fig


def snapshot_times(log: Mapping[str, Array], design_time_constant: float, count: int = 4) -> List[float]:
    """``count`` instants worth a look: shortly after the first contact, through the settling (five design
    time constants) and at the end of the contact (before a job's lift-off)."""
    t, patch = np.asarray(log["t"]), np.asarray(log["patch"])
    touching = np.nonzero(patch[:, _COLUMN["normal_force"]] > 0)[0]
    if not touching.size:
        return [float(t[-1])]
    end = len(t) - 1
    if "lifting" in log:
        lifting = np.nonzero(np.asarray(log["lifting"])[:, 0] > 0.5)[0]
        end = int(lifting[0]) - 1 if lifting.size else end
    first, last = float(t[touching[0]]), float(t[max(end, touching[0])])
    settle = min(first + 5 * design_time_constant, last)
    return sorted({first + 0.02, *np.linspace(first + 0.25 * (settle - first), settle, count - 2)[:count - 2], last})


def save_patch_plots(result: Any, out: Path) -> List[Path]:
    """patch_pressure.png (the pressure over the disc at ``snapshot_times``) and patch.png (the patch's
    figures over the run) of a run's ``result`` in ``out``."""
    scenario, log, summary = result.scenario, result.log, result.summary
    tool = scenario.robot.tool
    radius = float(tool.radius) if tool is not None and tool.is_disc else None
    plt = _pyplot()
    files = []
    snapshots = pressure_snapshots(scenario, log, snapshot_times(log, summary.design_time_constant or 0.1))
    fig = plot_pressure_snapshots(snapshots, radius)
    fig.savefig(out / "patch_pressure.png", dpi=110)
    plt.close(fig)
    files.append(out / "patch_pressure.png")
    commanded = np.asarray(log["desired_force"])[:, 0]
    fig = plot_patch_history(log, float(np.max(np.abs(commanded))) if commanded.size else None)
    fig.savefig(out / "patch.png", dpi=110)
    plt.close(fig)
    files.append(out / "patch.png")
    return files
