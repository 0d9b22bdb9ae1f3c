"""Regenerate the stability map and the Monte Carlo table of docs/stability.md.

    python docs/make_stability.py [--workers N] [--out DIR]

Runs the two sweeps in docs/sweeps/ on a local Dask cluster (resuming what an
earlier run of this script left in --out), writes the figures to docs/figures/
and prints the tables and numbers quoted in docs/stability.md.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

from drake_hybrid.experiments.sweep import run_sweep
from drake_hybrid.experiments.sweep_results import column, read_results
from drake_hybrid.experiments.sweep_spec import load_spec
from drake_hybrid.experiments.theory_verdict import theory_on_plane
from drake_hybrid.tasks.config import load_config
from drake_hybrid.viz.sweep_plots import monte_carlo_figure, stability_map_figure

DOCS = Path(__file__).resolve().parent
FIGURES = DOCS / "figures"
TASK = "window-washing"


def run(name, args):
    spec = load_spec(path=DOCS / "sweeps" / f"{name}.yaml")
    out = Path(args.out) / name
    resume = (out / "results.csv").exists()
    sweep = run_sweep(TASK, spec, out, workers=args.workers, resume=resume)
    print(f"{name}: {sweep.evaluated} points evaluated in {sweep.wall_time:.0f} s on {sweep.workers} "
          f"({sweep.points} in the spec, {sweep.failures} with errors)")
    return spec, out, read_results(out)


def stability_map(args):
    spec, out, rows = run("window_washing_map", args)
    base = load_config(path=out / "base_config.yaml")
    x, y, facet = spec.map["x"], spec.map["y"], spec.map["facet"]
    fig = stability_map_figure(rows, x, y, facet=facet, color="worst_discrete_real",
                               theory=lambda xs, ys, f: theory_on_plane(base, x, y, xs, ys, fixed={facet: f}),
                               title="window washing: sampled-loop stability (colour) and simulation (markers)")
    fig.savefig(FIGURES / "stability_map_window_washing.png", dpi=130)
    summary = {}
    print("\nlargest K_fp that settles in simulation (and has all sampled-loop multipliers inside the unit circle)")
    moduli = sorted({row[x] for row in rows})
    print("| pad modulus (Pa) | " + " | ".join(f"h = {h * 1000:g} ms: simulation / discrete eig. / both"
                                                for h in sorted({row[facet] for row in rows})) + " |")
    print("|---|" + "---|" * len({row[facet] for row in rows}))
    for modulus in moduli:
        cells = []
        for period in sorted({row[facet] for row in rows}):
            subset = [r for r in rows if r[x] == modulus and r[facet] == period]
            if all(r["error"] and r["stable_simulation"] is None for r in subset):
                cells.append("start not found (error recorded)")
                continue
            largest = lambda key: max([r[y] for r in subset if r[key]], default=None)
            values = [largest("stable_simulation"), largest("stable_discrete"), largest("stable")]
            cells.append(" / ".join("none" if v is None else f"{v:g}" for v in values))
            summary[f"{modulus:g}@{period:g}"] = values
        print(f"| {modulus:.3g} | " + " | ".join(cells) + " |")
    agree = [r for r in rows if r["stable_simulation"] is not None and r["stable_discrete"] is not None]
    disagree = [r for r in agree if r["stable_simulation"] != r["stable_discrete"]]
    continuous = [r for r in agree if r["stable_continuous"] is not None]
    print(f"\nsimulation and sampled-loop eigenvalues agree on {len(agree) - len(disagree)} of {len(agree)} points")
    for r in disagree:
        print(f"  disagree: E = {r[x]:.3g}, K_fp = {r[y]:g}, h = {r[facet]:g}: simulation {r['stable_simulation']}, "
              f"discrete {r['stable_discrete']} (worst Re {r['worst_discrete_real']:.3g} 1/s, "
              f"steady |e_f| {r['steady_force_error']:.3g} ({r['steady_force_row']}), "
              f"|e_v| {r['steady_velocity_error']:.3g} ({r['steady_velocity_row']}))")
    wrong = [r for r in continuous if r["stable_continuous"] != r["stable_simulation"]]
    print(f"continuous linearization (sampling not seen) disagrees with the simulation on {len(wrong)} of "
          f"{len(continuous)} points")
    failures = [r for r in rows if r["error"]]
    print(f"{len(failures)} points with an error; e.g. {failures[0]['error'][:160] if failures else ''}")
    walls = column(rows, "wall_time")
    print(f"point wall time: median {np.nanmedian(walls):.2f} s, max {np.nanmax(walls):.2f} s")
    return summary


def monte_carlo(args):
    spec, out, rows = run("window_washing_monte_carlo", args)
    fig = monte_carlo_figure(rows, group="control_period")
    fig.savefig(FIGURES / "monte_carlo_window_washing.png", dpi=130)
    print("\nMonte Carlo, payload mass 0.8-1.2 x nominal (controller: nominal)")
    print("| control period | points | settle (sim.) | discrete eig. stable | steady max abs(e_f) (N): median / 95 % / max "
          "| steady max abs(e_v), worst row in its units: median / 95 % / max | force settling 1 % (s): median / max | peak abs(F) (N): max |")
    print("|---|---|---|---|---|---|---|---|")
    table = {}
    for period in sorted({row["control_period"] for row in rows}):
        subset = [r for r in rows if r["control_period"] == period]
        stat = lambda name: column(subset, name)
        ef, ev, ts, pf = (stat(n) for n in ("steady_force_error", "steady_velocity_error", "force_settling_time",
                                             "peak_force"))
        settled = sum(1 for r in subset if r["stable_simulation"])
        discrete = sum(1 for r in subset if r["stable_discrete"])
        q = lambda a: f"{np.nanmedian(a):.3g} / {np.nanpercentile(a, 95):.3g} / {np.nanmax(a):.3g}"
        print(f"| {period * 1000:g} ms | {len(subset)} | {settled} | {discrete} | {q(ef)} | {q(ev)} | "
              f"{np.nanmedian(ts):.3g} / {np.nanmax(ts):.3g} | {np.nanmax(pf):.3g} |")
        table[f"{period:g}"] = {"points": len(subset), "settled": settled, "discrete_stable": discrete,
                                "steady_force_error": [float(np.nanmedian(ef)), float(np.nanpercentile(ef, 95)),
                                                       float(np.nanmax(ef))]}
    scale = column(rows, "model_error.payload_mass_scale")
    ef = column(rows, "steady_force_error")
    print(f"payload scale drawn: {np.min(scale):.3f} .. {np.max(scale):.3f}; "
          f"corr(scale, steady |e_f|) = {np.corrcoef(scale, ef)[0, 1]:.2f}")
    return table


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="runs/docs-stability")
    args = parser.parse_args()
    FIGURES.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    results = {"map": stability_map(args), "monte_carlo": monte_carlo(args)}
    results["wall_time"] = time.perf_counter() - start
    print(f"\ntotal wall time {results['wall_time'] / 60:.1f} min")
    (Path(args.out) / "summary.json").write_text(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
