"""Regenerate the figures in docs/figures (used by README.md and the docs).

    python docs/make_figures.py

Runs the tasks with their default configs and copies the tracking plots; the
numbers in the captions come from the same runs (printed here).
"""

import shutil
import sys
import tempfile
from pathlib import Path

from drake_hybrid.simulation import simulate, write_run
from drake_hybrid.tasks import get_task

FIGURES = Path(__file__).resolve().parent / "figures"


def window_washing():
    result = simulate(get_task("window-washing").default_config())
    with tempfile.TemporaryDirectory() as tmp:
        write_run(result, tmp)
        shutil.copy(Path(tmp) / "velocity_tracking.png", FIGURES / "window_washing_velocity.png")
        shutil.copy(Path(tmp) / "force_tracking.png", FIGURES / "window_washing_force.png")
    s = result.summary
    print(f"window-washing: settles within 1 % after {s['velocity_settling_time_1_percent']:.3f} s (velocity), "
          f"{s['force_settling_time_1_percent']:.3f} s (force); design time constant {s['design_time_constant']} s")


def main(names):
    FIGURES.mkdir(parents=True, exist_ok=True)
    makers = {"window-washing": window_washing}
    for name in names or makers:
        makers[name]()


if __name__ == "__main__":
    main(sys.argv[1:])
