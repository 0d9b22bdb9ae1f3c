"""Regenerate the figures in docs/figures (used by README.md and the docs).

    python docs/make_figures.py                 # all of them
    python docs/make_figures.py eigenvalues     # some: window-washing, eigenvalues, diagram, animations, tutorials

Every figure comes from a run made here; the numbers quoted in the captions
are printed by the same runs. ``diagram`` needs Graphviz's ``dot``
(``apt-get install graphviz``); ``animations`` needs Chromium (``apt-get
install chromium``) and, for the Panda, the test extra (``example-robot-data``).
``tutorials`` runs tutorials 2 and 3 at full length and keeps the figures they
save and frames of their animations (Chromium and the test extra, for nbclient).
"""

import copy
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.viz.outputs import write_run

FIGURES = Path(__file__).resolve().parent / "figures"
TUTORIALS = Path(__file__).resolve().parents[1] / "tutorials"


def window_washing():
    result = simulate(get_task("window-washing").default_config())
    with tempfile.TemporaryDirectory() as tmp:
        write_run(result, tmp)
        shutil.copy(Path(tmp) / "velocity_tracking.png", FIGURES / "window_washing_velocity.png")
        shutil.copy(Path(tmp) / "force_tracking.png", FIGURES / "window_washing_force.png")
    s = result.summary
    print(f"window-washing: settles within 1 % after {s.velocity_settling_time_1_percent:.3f} s (velocity), "
          f"{s.force_settling_time_1_percent:.3f} s (force); design time constant {s.design_time_constant} s")


def eigenvalues():
    """The window task's linearized closed loop against its design, and the force-gain sweep of
    tutorial 5 (where the contact mode becomes unstable)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from drake_hybrid.analysis.linearization import linearize_continuous
    from drake_hybrid.control.gains import HybridGains
    from drake_hybrid.viz import eigenvalue_plots

    base = get_task("window-washing").default_config()
    linearization = linearize_continuous(base)
    fig = eigenvalue_plots.eigenvalue_figure(linearization.match, title="window washing, velocity-force")
    fig.savefig(FIGURES / "window_washing_eigenvalues.png", dpi=110)
    plt.close(fig)
    match = linearization.match
    print("window-washing eigenvalues: designed", match.predicted.round(4).tolist(), "linearized partners",
          match.partner.round(4).tolist(), "worst relative error", f"{match.relative_error.max():.4f}")
    gains = [7.5, 15, 30, 60, 90, 120, 180]
    sweep = []
    for K_fi in gains:
        config = copy.deepcopy(base)
        config.gains = HybridGains(velocity=base.gains.velocity, force_proportional=base.gains.force_proportional,
                                   force_integral=[K_fi])
        sweep.append(linearize_continuous(config))
        extra = sweep[-1].match.extra
        mode = extra[extra.imag.argmax()]
        print(f"  K_fi = {K_fi:5.1f}: contact mode {mode.real:+.2f} {mode.imag:+.2f}j 1/s")
    fig = eigenvalue_plots.eigenvalue_sweep_figure(gains, sweep, "force integral gain K_fi", units="1/s",
                                                   zoom=((-130, 25), (-170, 170)),
                                                   title="window washing: closed-loop eigenvalues against K_fi")
    fig.savefig(FIGURES / "force_gain_sweep.png", dpi=110)
    plt.close(fig)


def diagram():
    """Drake's own picture of the closed loop (GetGraphvizString), rendered by Graphviz."""
    from drake_hybrid.scenario.builder import build_scenario

    dot = shutil.which("dot")
    if dot is None:
        raise SystemExit("the diagram needs Graphviz's dot: apt-get install graphviz")
    scenario = build_scenario(get_task("window-washing").default_config(), with_loggers=False)
    source = scenario.diagram.GetGraphvizString(max_depth=1)
    subprocess.run([dot, "-Tsvg", "-o", str(FIGURES / "closed_loop.svg")], input=source.encode(), check=True)
    print(f"wrote {FIGURES / 'closed_loop.svg'}")


def _screenshot(html, png, at):
    """A frame of the recorded animation at simulation time ``at`` (s)."""
    from drake_hybrid.viz.animation import HIDE_MESHCAT_CONTROLS, render_html

    report = render_html(html, png, times=(at,), width=900, height=520, style=HIDE_MESHCAT_CONTROLS, seek=True)
    if not report.clean:
        raise SystemExit(f"{html} did not render cleanly: {report.console_errors} {report.page_errors} "
                         f"{report.blocked_requests}")
    print(f"wrote {png}")


def animations():
    """Frames of the recorded 3-D animations: the window task, and the Panda of tutorial 6 (the
    notebook is run here, so the picture is the tutorial's own run)."""
    from drake_hybrid.viz.animation import quiet_meshcat, set_task_camera

    task = get_task("window-washing")
    meshcat = quiet_meshcat()
    set_task_camera(meshcat, task)
    result = simulate(task.default_config(), meshcat=meshcat, record_html=True)
    with tempfile.TemporaryDirectory() as tmp:
        html = Path(tmp) / "window_washing.html"
        html.write_text(result.html)
        _screenshot(html, FIGURES / "window_washing_3d.png", at=2.0)

        _run_tutorial("06_your_own_robot.ipynb", tmp)
        _screenshot(Path(tmp) / "panda_drum.html", FIGURES / "panda_drum_3d.png", at=1.5)


def _run_tutorial(name, workdir):
    """Execute a tutorial at full length (not the shortened test runs) with ``workdir`` as its folder,
    and print what it printed (the numbers the captions quote)."""
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.read(TUTORIALS / name, as_version=4)
    os.environ.pop("DRAKE_HYBRID_NOTEBOOK_TEST", None)
    NotebookClient(notebook, timeout=900, kernel_name="python3", resources={"metadata": {"path": workdir}}).execute()
    print(f"ran tutorials/{name}:")
    for cell in notebook.cells:
        for output in cell.get("outputs", []):
            if output.get("output_type") == "stream" and output.get("name") == "stdout":
                print("   ", output["text"].rstrip().replace("\n", "\n    "))


def tutorials():
    """The crank's and the sphere's figures, as tutorials 2 and 3 draw them from their own runs: the
    naive pseudo-velocity against Option A, the pole crossing, and a frame of each animation."""
    with tempfile.TemporaryDirectory() as tmp:
        _run_tutorial("02_crank_turning.ipynb", tmp)
        _run_tutorial("03_sphere_polishing.ipynb", tmp)
        for name in ("crank_pseudo_velocity.png", "sphere_pole_crossing.png"):
            shutil.copy(Path(tmp) / name, FIGURES / name)
            print(f"wrote {FIGURES / name}")
        _screenshot(Path(tmp) / "crank_turning.html", FIGURES / "crank_turning_3d.png", at=0.8)
        _screenshot(Path(tmp) / "sphere_pole_crossing.html", FIGURES / "sphere_pole_crossing_3d.png", at=0.7)


def main(names):
    FIGURES.mkdir(parents=True, exist_ok=True)
    makers = {"window-washing": window_washing, "eigenvalues": eigenvalues, "diagram": diagram,
              "animations": animations, "tutorials": tutorials}
    unknown = sorted(set(names) - set(makers))
    if unknown:
        raise SystemExit(f"unknown figures {unknown}; choose from {sorted(makers)}")
    for name in names or makers:
        makers[name]()


if __name__ == "__main__":
    main(sys.argv[1:])
