"""Regenerate docs/baselines.md's numbers, table and figures.

    python docs/make_baselines.py [--quick]

1. The Raibert-Craig instability on the planar 2R arm at the hinted configuration: Drake's
   linearization against the analytic joint-servo eigenvalue, the growth rate in simulation; Fisher-
   Mujtaba and Li & Sastry at the same point.
2. The stability map over the configuration space (figure docs/figures/baselines_stability_map.png).
3. The window task with every law (table; docs/baselines.json): velocity and force errors after five
   design time constants, 1 % settling times, and the linearized closed loop's slowest and worst
   eigenvalues.
4. The crank's worst relative eigenvalue deviation from the design, paper form against the modelled
   mechanism and tool (mechanism.source: plant, sensor.compensate_tool_inertia).

``--quick`` shortens the window runs (for the test that checks the table regenerates).
"""

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from report_format import significant  # noqa: E402  (docs/: figures rounded, reruns rewrite nothing)

from drake_hybrid.analysis import kinematic_instability as ki  # noqa: E402
from drake_hybrid.analysis.discrete_linearization import linearize_discrete  # noqa: E402
from drake_hybrid.analysis.linearization import linearize_continuous  # noqa: E402
from drake_hybrid.experiments.simulation import simulate  # noqa: E402
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.viz.eigenvalue_plots import joint_servo_map_figure  # noqa: E402

DOCS = Path(__file__).resolve().parent
EVALUATION_TIME = 1.0         # s: the window errors are the largest after this (five of K_v = 10's time constants)
MARGINAL = 0.05              # 1/s: slower real parts are the predicted zeros (as analysis.match_eigenvalues)
FIGURES = DOCS / "figures"
# The laws of the window table: (label, controller, mode).
WINDOW_LAWS = [("Li & Sastry, velocity/force (3.1-12)", "li-sastry", "velocity-force"),
               ("Li & Sastry, position/force (Remark 3)", "li-sastry", "position-force"),
               ("Raibert-Craig, J^-1 S joint servo", "raibert-craig", "position-force"),
               ("Fisher-Mujtaba, (S J)^+ S joint servo", "fisher-mujtaba", "position-force"),
               ("PD + open-loop force (manipulation course)", "pd-open-loop-force", "position-force")]


def instability():
    """Section 1: {controller: {linearized, analytic, growth}} at the hinted configuration."""
    results = {}
    for controller in ki.CONTROLLERS:
        loop = ki.build_two_link_loop(controller)
        eigenvalues, A = ki.linearized_eigenvalues(loop)
        analytic = ki.analytic_eigenvalues(controller)
        entry = {"worst_linearized": float(eigenvalues.real.max()), "worst_analytic": float(analytic.real.max())}
        if controller == "raibert-craig":
            entry["simulated_growth"], _ = ki.simulated_growth_rate(loop, A)
        results[controller] = entry
    return results


def stability_map_figure(points=121):
    """Section 2: the map; returns the unstable fraction of Raibert-Craig's regular grid points."""
    q = np.linspace(-np.pi, np.pi, points)
    maps = ki.stability_map(q, q)
    fig = joint_servo_map_figure(q, q, maps, marked=ki.HINTED_CONFIGURATION, title=(
        f"2R arm, x position-controlled, z force-controlled; K_q = {ki.JOINT_GAINS} 1/s, "
        f"K_s = {ki.SERVO_RATE:g} 1/s (Li & Sastry: -1, -5 everywhere)"))
    FIGURES.mkdir(exist_ok=True)
    fig.savefig(FIGURES / "baselines_stability_map.png", dpi=120)
    plt.close(fig)
    regular = np.isfinite(maps["raibert-craig"])
    return {name: float(np.mean(maps[name][regular] > 0)) for name in maps}


def window_table(duration=None):
    """Section 3: one row per law on the paper's window task."""
    task = get_task("window-washing")
    rows = []
    for label, controller, mode in WINDOW_LAWS:
        config = task.default_config().replace(controller=controller, mode=mode)
        # The PD's row stiffness and damping: Li & Sastry's K_p and K_v (the same design on a free row).
        config.baseline.stiffness, config.baseline.damping = list(config.gains.position), list(config.gains.velocity)
        if duration is not None:
            config.duration = duration
        run = simulate(config)
        summary, log = run.summary, run.log
        late = log["t"] >= EVALUATION_TIME
        scales = summary.command_scales
        linear = linearize_continuous(config)
        real = linear.eigenvalues.real
        slow = real[real < -MARGINAL]                   # the zeros (unregulated tangent position, ...) left out
        rows.append({"law": label, "controller": controller, "mode": mode,
                     "velocity_error_percent": float(100 * np.abs(log["velocity_error"][late]).max() / scales["speed"]),
                     "force_error_percent": float(100 * np.abs(log["force_error"][late]).max() / scales["force"]),
                     "velocity_settling_s": summary.velocity_settling_time_1_percent,
                     "force_settling_s": summary.force_settling_time_1_percent,
                     "worst_real": float(real.max()), "slowest_stable": float(slow.max()) if slow.size else None})
    return rows


def crank_deviations():
    """Section 4: worst relative eigenvalue deviation (%) per mode, paper form and modelled."""
    task = get_task("crank-turning")
    table = {}
    for mode in ("velocity-force", "position-force", "impedance-force"):
        entry = {}
        for form, modelled in (("paper", False), ("modelled", True)):
            config = task.default_config().replace(mode=mode)
            if modelled:
                config.mechanism.source = "plant"
                config.sensor.compensate_tool_inertia = True
            result = linearize_discrete(config, settle_time=0.5)
            entry[form] = float(100 * result.match.relative_error.max())
        table[mode] = entry
    return table


def _fmt(value, digits=3):
    return "n/a" if value is None else f"{value:.{digits}g}"


def report_lines(rounded):
    """The lines main() prints, from the figures as baselines.json has them (``significant``), so that
    stdout shows no float noise and the same figures as the tracked file."""
    rc = rounded["instability"]["raibert-craig"]
    lines = [f"Raibert-Craig at q = (-160, 30) deg: linearized {rc['worst_linearized']:+.4f} 1/s, analytic "
             f"{rc['worst_analytic']:+.4f}, simulated growth {rc['simulated_growth']:+.4f} "
             f"({100 * (rc['simulated_growth'] / rc['worst_linearized'] - 1):+.3f} %)"]
    for name in ("fisher-mujtaba", "li-sastry", "pd-open-loop-force"):
        lines.append(f"{name}: worst linearized real part {rounded['instability'][name]['worst_linearized']:+.4f} 1/s")
    lines.append("unstable fraction of the regular grid: " + ", ".join(
        f"{name} {100 * fraction:.4g} %" for name, fraction in rounded["unstable_fraction"].items()))
    lines += ["", "| law | velocity error after 1 s (%) | force error after 1 s (%) | settling 1 % velocity / force (s) "
              "| slowest stable eigenvalue (1/s) | largest real part (1/s) |", "|---|---|---|---|---|---|"]
    for row in rounded["window"]:
        lines.append(f"| {row['law']} | {_fmt(row['velocity_error_percent'])} | {_fmt(row['force_error_percent'])} | "
                     f"{_fmt(row['velocity_settling_s'])} / {_fmt(row['force_settling_s'])} | "
                     f"{_fmt(row['slowest_stable'])} | {_fmt(row['worst_real'])} |")
    lines += ["", "| crank mode | paper form: worst deviation (%) | modelled mechanism and tool (%) |", "|---|---|---|"]
    for mode, entry in rounded["crank"].items():
        lines.append(f"| {mode} | {entry['paper']:.2f} | {entry['modelled']:.2f} |")
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="1.5 s window runs (the test's setting)")
    args = parser.parse_args()
    results = {"instability": instability(), "unstable_fraction": stability_map_figure(),
               "window": window_table(duration=1.5 if args.quick else None), "crank": crank_deviations()}
    # Six figures for the instability: the simulated growth agrees with the linearization to 1e-4 relative.
    rounded = {**significant(results), "instability": significant(results["instability"], digits=6)}
    (DOCS / "baselines.json").write_text(json.dumps(rounded, indent=1) + "\n")
    print("\n".join(report_lines(rounded)))


if __name__ == "__main__":
    main()
