"""The acceptance runs of path jobs: whole jobs from the first touch to the last with a 6-DOF arm (the UR5e).

* the built-in task ``surface-polishing``: a raster over a 10 cm x 10 cm patch of the 15 cm sphere at
  5 cm/s and 10 N (2 cm between lines), approach to lift-off;
* the same job on a part given as a height map, from a task file (``models/tasks/raster_bump.yaml``:
  a Gaussian bump, 41 x 41 samples), and on the built-in saddle height map;
* the closed loop's eigenvalues at the middle of each path (``path.hold_at`` 0.5,
  ``linearize_continuous``) against the design.

* a sweep of the line spacing on the local Dask cluster (``docs/sweeps/raster_spacing.yaml``, two
  workers): each point the whole job and its linearizations;
* every surface kind (a tilted plane, a sphere, a cylinder off its top line, a height map) from a task file
  (the UR10 of example-robot-data) and from a user's own diagram (the Franka Panda of example-robot-data):
  the normal force from the logged wrench along the true normal, and the loop held at five points of a path
  whose force changes along it (``docs/path_surfaces.py``).

Writes docs/paths.json, docs/paths.md and the figures docs/figures/paths_*.png.

    python docs/paths.py              # all, about 45 minutes on a quiet machine
    python docs/paths.py --sweep      # the sweep only (about 4 minutes), into docs/paths.json and the page
    python docs/paths.py --surfaces   # every surface kind only (about 25 minutes), into docs/paths.json and the page
    python docs/paths.py --page       # the page again from docs/paths.json
"""

import dataclasses
import json
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
from report_format import significant  # noqa: E402

import path_surfaces  # noqa: E402

from drake_hybrid.analysis.linearization import linearize_continuous  # noqa: E402
from drake_hybrid.experiments.simulation import simulate  # noqa: E402
from drake_hybrid.experiments.sweep import run_sweep  # noqa: E402
from drake_hybrid.experiments.sweep_results import read_results  # noqa: E402
from drake_hybrid.experiments.sweep_spec import load_spec  # noqa: E402
from drake_hybrid.tasks.path import job_duration, with_path
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task_file import load_task_file
from drake_hybrid.viz.path_plots import save_path_plots  # noqa: E402

logging.getLogger("drake").setLevel(logging.ERROR)
FIGURES = ROOT / "docs" / "figures"


def line_changes(log, report):
    """At each segment's start: the commanded acceleration's step and the peaks of the errors in the
    segment's first five design time constants (what the page explains)."""
    t = np.asarray(log["t"])
    rows = []
    for segment in report.segments:
        start = segment.start
        window = (t >= start) & (t < start + report.settle_time_per_segment_s)
        rows.append({"segment": segment.segment, "start": start,
                     "velocity_error_peak": float(np.max(np.abs(log["velocity_error"][window, 1:]))),
                     "spin_error_peak": float(np.max(np.abs(log["velocity_error"][window, 0]))),
                     "tangential_force_peak": float(np.max(np.abs(log["tangential_force"][window, 1:]))),
                     "path_error_along_surface_mm": segment.transient_max_path_error_along_surface_mm,
                     "force_error_percent": segment.transient_max_force_error_percent})
    return rows


def job(name, task_name, config):
    result = simulate(config)
    summary = result.summary
    for path in save_path_plots(result.log, summary, FIGURES):
        path.rename(FIGURES / f"paths_{name}_{path.stem.replace('path_', '')}.png")
    linear = linearize_continuous(with_path(config, hold_at=0.5))
    return {"name": name, "task": task_name, "duration": config.duration, "wall_time": summary.wall_time,
            "report": summary.path.as_dict(), "line_changes": line_changes(result.log, summary.path),
            "velocity_rows": [row.as_dict() for row in summary.velocity_rows],
            "force_rows": [row.as_dict() for row in summary.force_rows],
            "eigenvalue_error": float(np.max(linear.match.relative_error)), "matched": bool(linear.match.matched),
            "designed": [[float(e.real), float(e.imag)] for e in linear.match.predicted],
            "linearized": [[float(e.real), float(e.imag)] for e in linear.match.partner],
            "jacobian_check": float(linear.jacobian_check.max_relative_error), "jacobian_used":
                linear.jacobian_check.used}


def step_halved():
    """The line changes' transient on a short raster (two 4 cm lines 2 cm apart) with the plant and the
    controller at 1 ms and at 0.5 ms: the peak distance along the surface in the later segments' first five
    design time constants (mm), against h v / 2 (the discrete plant's half-step lead at the path's speed)."""
    task = get_task("surface-polishing")
    figures = []
    for step in (1e-3, 5e-4):
        config = task.default_config()
        config = with_path(config, pattern=dataclasses.replace(config.path.pattern, size=[0.04, 0.02], spacing=0.02))
        config.duration = job_duration(task, config)
        config.plant.time_step = config.control_period = config.log_period = step
        report = simulate(config).summary.path
        peaks = [s.transient_max_path_error_along_surface_mm for s in report.segments[1:]]
        figures.append({"time_step": step, "line_change_peak_mm": max(peaks),
                        "half_step_lead_mm": 1000 * step * config.path.speed / 2})
    return figures


SWEEP_COLUMNS = ("path.pattern.spacing", "stable", "stable_simulation", "stable_continuous", "stable_discrete",
                 "path_error_mm", "path_error_along_surface_mm", "path_force_error_percent", "path_time_off_surface",
                 "path_fraction_run", "worst_continuous_real", "worst_discrete_real", "wall_time")


def sweep():
    """The line spacing's sweep on a local Dask cluster of two workers: its rows (the columns above)."""
    with tempfile.TemporaryDirectory() as folder:
        run_sweep("surface-polishing", load_spec(path=ROOT / "docs" / "sweeps" / "raster_spacing.yaml"), folder,
                  workers=2, progress=False)
        rows = read_results(Path(folder) / "results.csv")
    return sorted(({key: row.get(key) for key in SWEEP_COLUMNS} for row in rows),
                  key=lambda row: row["path.pattern.spacing"])


def run():
    """Every part, each written to docs/paths.json (and the page) as soon as it is measured: a part that fails
    leaves the ones before it."""
    results = []
    task = get_task("surface-polishing")
    results.append(job("sphere", "surface-polishing", task.default_config()))
    bump_task, bump_config = load_task_file(ROOT / "models" / "tasks" / "raster_bump.yaml")
    results.append(job("bump", "models/tasks/raster_bump.yaml", bump_config))
    results.append(job("saddle", "surface-polishing --option workpiece=saddle",
                       task.default_config(options={"workpiece": "saddle"})))
    everything = json.loads((ROOT / "docs" / "paths.json").read_text())
    everything["jobs"] = results
    for part, measure in (("step_halved", step_halved), ("sweep", sweep), ("surfaces", path_surfaces.run)):
        write(everything)
        everything[part] = measure()
    return everything


def _mm(value):
    return "" if value is None else f"{value:.3f}"


def page(everything):
    results, halved = everything["jobs"], everything["step_halved"]
    rows = ["| job | path | settled path error: in all / along the surface / along the normal (mm) | force error (%) "
            "| at the line changes: along the surface (mm) / force (%) | after the approach (segment 0) | off the "
            "surface (s) | eigenvalues: worst (%) | Jacobian |", "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        p = r["report"]
        later = r["line_changes"][1:]
        first = r["line_changes"][0]
        rows.append(f"| {r['name']} (`{r['task']}`) | {p['length_m']:.3f} m, {p['segments_run']} segments, "
                    f"{'completed' if p['completed'] else 'NOT completed'} | {_mm(p['max_path_error_mm'])} / "
                    f"{_mm(p['max_path_error_along_surface_mm'])} / {_mm(p['max_path_error_along_normal_mm'])} | "
                    f"{p['max_force_error_percent']:.3f} | "
                    f"{_mm(max(c['path_error_along_surface_mm'] for c in later))} / "
                    f"{max(c['force_error_percent'] for c in later):.3f} | "
                    f"{_mm(first['path_error_along_surface_mm'])} mm / {first['force_error_percent']:.3f} % | "
                    f"{p['time_off_surface_s']:.3f} | "
                    f"{100 * r['eigenvalue_error']:.2f} | {r['jacobian_check']:.1e} ({r['jacobian_used']}) |")
    changes = ["| job | segment | start (s) | velocity error peak (mm/s) | spin error peak (rad/s) | F_v peak (N) "
               "| path error along the surface (mm) | force error (%) |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        for c in r["line_changes"]:
            changes.append(f"| {r['name']} | {c['segment']} | {c['start']:.3f} | {1000 * c['velocity_error_peak']:.3f} | "
                           f"{c['spin_error_peak']:.4f} | {c['tangential_force_peak']:.3f} | "
                           f"{_mm(c['path_error_along_surface_mm'])} | {c['force_error_percent']:.3f} |")
    halving = "\n".join(f"| {1000 * h['time_step']:.1f} ms | {1000 * h['line_change_peak_mm']:.1f} | "
                         f"{1000 * h['half_step_lead_mm']:.1f} |" for h in halved)
    swept = "\n".join(
        f"| {100 * r['path.pattern.spacing']:.0f} cm | {r['stable']} ({r['stable_simulation']}, {r['stable_continuous']}, "
        f"{r['stable_discrete']}) | {r['path_error_mm']:.3f} / {r['path_error_along_surface_mm']:.3f} | "
        f"{r['path_force_error_percent']:.3f} | {r['path_time_off_surface']:.3f} | {r['path_fraction_run']:.2f} | "
        f"{r['worst_continuous_real']:.2f} / {r['worst_discrete_real']:.2f} | {r['wall_time']:.0f} |"
        for r in everything.get("sweep", []))
    return PAGE.format(table="\n".join(rows), changes="\n".join(changes), halving=halving, swept=swept,
                       surfaces=path_surfaces.table(everything.get("surfaces", [])),
                       surfaces_note=SURFACES_NOTE)


PAGE = """# Jobs over a surface: a path at a force from the first touch to the last

Generated by `python docs/paths.py` (the acceptance runs of whole jobs). Each job: a UR5e (6 joints, airo-models)
with the 20 mm compliant ball pad, the contact supervisor's guarded approach from 5 mm above the path's first
point at 2 cm/s, 0.3 s pressing there, a raster (boustrophedon) over a 10 cm x 10 cm patch seen from above,
lines 2 cm apart, at most 5 cm/s and 0.5 m/s^2 (Drake's Toppra), the normal force 10 N, and the lift-off
(1 cm) when the path ends; position-force mode (Remark 3) with the position error measured against the path
(`systems.path_source.PathSource`), gains K_v = 30, K_p = 200 on every velocity row (roots -10, -20), K_fp =
0.5, K_fi = 15 (-10), held orientation rows -15, -30: five design time constants are 0.5 s. The simulation:
Drake's discrete SAP hydroelastic contact at 1 kHz, the controller sampled at 1 kHz.

"Settled": over every segment (a raster line or the step to the next) from its start + five design time
constants to its end. "Force error": the normal force the sensor measured (its wrench along the surface's
normal) against the command, not the controller's own force row. "Path error": the distance of the pad centre
from its reference point on C = 0; "along
the surface" is its part in the tangent plane (where on the workpiece the pad is), "along the normal" the rest,
which is the compliant pad's compression at 10 N (the reference lies on C = 0, the pressed pad inside it; the
force loop sets the compression, it is not tracked). "At the line changes": the same over each segment's first
five design time constants. Eigenvalues: the continuous closed loop held at the middle of the path
(`path.hold_at` 0.5), the worst relative distance of a designed eigenvalue from its linearized partner;
"Jacobian": Drake's AutoDiffXd A against central differences (`analysis.derivatives`).

{table}

The targets: a path error within 1 mm and a force within 2 % after each segment's first five design time
constants, and eigenvalues within 5 % of the design. Along the surface the pad stays within a few hundredths
of a millimetre of its reference; the distance in all is the pad's compression (0.89 mm on the sphere; on the
bump's top, a 3 cm convex radius, the pad sinks deeper at the same force and the distance in all exceeds 1 mm
by the compression alone, 1.05 mm: not a tracking error, but over the 1 mm target if the compression is
counted). The line changes' transients are a few hundredths of a millimetre (below); the approach's, in the
first segment, a few tenths.

## The line changes

The pad stops at each corner: a segment ends at rest and the next starts from rest, and Toppra's acceleration
is piecewise constant, so at a line change the commanded acceleration steps by up to 0.5 m/s^2 along the new
direction. The law's feed-forward r-ddot_pd carries the step exactly (in the rigid model a line change
leaves no error), so what remains is what the compliant, sampled loop adds:

{changes}

**Why.** Drake's discrete plant advances the positions with the velocities at the end of each step,
q_(k+1) = q_k + h v_(k+1) (semi-implicit Euler). A motion at speed v is then sampled h v / 2 ahead of the
continuous motion the reference describes: 25 um at h = 1 ms and 5 cm/s. Each acceleration from rest (0.1 s
at 0.5 m/s^2) builds that lead, the position loop (roots -10, -20) removes it within its five time
constants, and each deceleration to rest builds the opposite lag: the peaks at the line changes, and the
largest errors inside the settled windows, which end with their segment's deceleration. The law itself
follows the step of the commanded acceleration (its feed-forward carries it), and the contact adds nothing
visible there: the measured tangential force F_v (about 1 mN on the sphere and the saddle, up to 40 mN on the
bump's tessellated mesh) is cancelled by the law as measured, and the peaks are the same on all three
workpieces and at every line change. Halving the step halves the
transient (a short raster of two 4 cm lines 2 cm apart, the plant and the controller at the same period):

| period | peak along the surface at the line changes (um) | h v / 2 (um) |
|---|---|---|
{halving}

The first segment's transient is the approach's, not a line change: the path starts 0.3 s after the first
contact (`path.dwell`), before the landing's transient (the pad arriving at 2 cm/s, the force rising from
the contact threshold to 10 N) has decayed, so it is larger there.

## A sweep of the line spacing on the local Dask cluster

`drake-hybrid sweep surface-polishing --grid docs/sweeps/raster_spacing.yaml --workers 2`: the job on a
4 cm x 4 cm patch of the sphere with lines 1, 2 and 4 cm apart, each point a whole job (`path_*` columns,
the steady window ending at the lift-off) and the two linearizations at the path's first point (`stable`:
the simulation's verdict and the sampled loop's; the continuous one in brackets).

| spacing | stable (simulation, continuous, discrete) | path error: in all / along the surface (mm) | force error (%) | off the surface (s) | path run | worst real part: continuous / discrete (1/s) | wall time (s) |
|---|---|---|---|---|---|---|---|
{swept}

The settled path figures agree at every spacing to the digits shown: the lines are as long at every
spacing, and a line's largest settled error along the surface is the half-step lag its deceleration builds
(above), which the spacing does not change.

## Every surface kind, from a task file and from your own diagram

`python docs/paths.py --surfaces` (`docs/path_surfaces.py`): the same job, short (two 3 cm raster lines 1.5 cm
apart: three segments, the step between the lines too short for a settled part), on arms the package does not
ship and on surfaces it does not demo: a plane tilted by 15 degrees, a sphere (radius 15 cm), a cylinder lying
along y (radius 10 cm) with the lines 13 to 22 degrees off its top line, and the 3 cm bump as a height map,
with the path on its flank. From a task file (written by the script: the UR10 of example-robot-data by
`robot.loader`, `workpiece.surface`, run by `simulate`) and from a user's own diagram (the Franka Panda of
example-robot-data by `load_arm`, the blocks of `drake_hybrid.station`, `solve_path_start`, Drake's
Simulator). The normal force is computed from the logged wrench (the sensor's own) along the true normal at
the pad centre: the part's normal at its closest point to the pad centre, found from the logged joint
positions; beside it, the path report's figure (the same wrench along the reference's normal). The
eigenvalues: the continuous loop held at h = 0, 0.25, 0.5, 0.75 and 1 of the same path with the force
changing along it by arc length from 6 N to 14 N (`path.hold_at`, `force_by_arc_length`): `linearize_continuous`
for the task file, `solve_path_start` and `linearize_at_contact` for the own diagram; the worst relative
distance of a designed eigenvalue from its linearized partner at each h, the modes with a positive real part
and the largest equilibrium residual.

{surfaces}

{surfaces_note}
"""


SURFACES_NOTE = ""


def write(results):
    (ROOT / "docs" / "paths.json").write_text(json.dumps(significant(results), indent=1) + "\n")
    (ROOT / "docs" / "paths.md").write_text(page(results))


if __name__ == "__main__":
    if "--page" in sys.argv:
        write(json.loads((ROOT / "docs" / "paths.json").read_text()))
    elif "--sweep" in sys.argv:
        everything = json.loads((ROOT / "docs" / "paths.json").read_text())
        everything["sweep"] = sweep()
        write(everything)
    elif "--surfaces" in sys.argv:
        everything = json.loads((ROOT / "docs" / "paths.json").read_text())
        everything["surfaces"] = path_surfaces.run()
        write(everything)
    else:
        write(run())
