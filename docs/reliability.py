"""Run every fault case of drake_hybrid.reliability and write the reliability report.

    python docs/reliability.py            # all cases, full horizons (1 to 2.5 minutes on 2 cores: 66 s idle, 134 s shared)
    python docs/reliability.py --quick    # the test horizons, no reference runs (under a minute)

Writes ``docs/reliability.md`` (the table, what each fault is, how each criterion was chosen,
the details), ``docs/reliability.json`` (the figures), ``docs/figures/reliability_contact_loss.png``
(the force through a contact loss and its re-acquisition) and replaces the table between the
``reliability-table`` markers in ``docs/results.md`` (the rows with a pass/fail; the reference rows are in
the report). Every number in those files comes from this run, rounded to four significant figures
(``report_format.significant``); run times and dates go to standard output only, so a rerun on an
unchanged tree leaves those files as they were.

A row that fails and is listed in ``KNOWN_FAILURES`` (tests/reliability_cases.py) is reported as a known
failure (``FAIL (known)``), not as a regression: the script exits 0 when the known ones are the only
failures, 1 on any other (``reliability_cases.exit_code``).
"""

import argparse
import json
import platform
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# The cases and their pass criteria live with the tests (tests/reliability_cases.py).
sys.path.insert(0, str(ROOT / "tests"))
import reliability_cases as reliability  # noqa: E402
from report_format import significant  # noqa: E402

START, END = "<!-- reliability-table:start -->", "<!-- reliability-table:end -->"
HEADER = ["fault", "magnitude", "figure measured", "measured", "criterion", "result"]

EXPLANATIONS = """\
## The faults and the protections

**Making and losing contact** (`supervision.ContactSupervisor`, the guarded move in
`HybridController`). A start off the surface (`start.in_contact: false`) or a surface that moves
away is handled by a state machine TARE -> APPROACH -> CONTACT (-> APPROACH on loss, -> HOLD when
no surface is found within `max_travel`). Off the surface the controller replaces the force rows'
a_f = 0 by the guarded move C-ddot = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r) (n_C = -F_d / |F_d|;
C_r the supervisor's approach reference, moving at s n_C from C at the start of APPROACH: a
velocity servo with integral action, double pole at -K_a, which cannot stall against the surface
below the contact threshold), sends no force feedforward along them and freezes the force
integral (anti-windup: a lost contact does not wind it up). Contact is declared when the force along F_d reaches 30 % of |F_d|, lost when it stays below
10 % for 10 ms. The re-contact bound is the time the guarded move needs in the worst case:
the loss dwell, the lift at the approach speed, and three time constants 1/K_a of the servo.
The impact grows with the approach speed (the speed sweep rows): with this pad (5 MPa, 20 mm ball)
the 3 |F_d| limit holds up to about 0.05 m/s; the default is 0.02 m/s.

**Sensor faults** (`faults.SensorFaultInjector` simulates them; `wrench_conditioner.WrenchConditioner`
protects the controller). Noise is attenuated by the force loop itself, by K_fp / (1 + K_fp) at
high frequency (the predicted figure, times sqrt(alpha / (2 - alpha)) for the conditioner's
first-order low-pass with alpha = 1 - exp(-2 pi f_c h)); the measured figure is a little above the
prediction with the 50 Hz filter, whose lag meets the 18 Hz contact mode. A constant bias cannot
be filtered: in contact from the start the loop regulates the biased reading, so the true force
is off by exactly -bias (the prediction, met); from free space the conditioner tares the sensor
during the supervisor's TARE phase and the error vanishes. Dropouts: a NaN sample is held for at
most `max_hold_time` (10 ms), then reported as NaN so that the controller ignores the wrench
(force error zero, integrals held: the force is then held by the feedforward -F_d alone) and the
supervisor makes no decision. A stale sensor (repeating its last sample) is recognized by its
sequence number; without the conditioner the force loop integrates the stale error for the whole
dropout (the reference row).

**Model error** (`tasks.config.ModelErrorConfig`, simulation plant only). Payload and link-inertia
errors are small for this arm and rejected: the force integral removes the force error, the
velocity error stays below 1 %. Joint friction is the large one: velocity-force mode has no
integral on the velocity rows, so friction leaves a steady velocity error that the rigid-contact
dynamics predict, e = K_v^-1 E_p J P (delta tau + J^T E_p^T F_v) with P the constrained
mobility (the measured tangential moment F_v of the tessellated ball pad included: without it
the prediction is about 20 % off). In position-force mode the wrist joint sticks: its loop gives
only I_3 K_p, about 0.4 N m per radian of position error, against 0.5 N m of Coulomb friction, so
the position error has to grow to about a radian before the joint slides (a reference row: the
paper's law has no friction compensation; raise the gains on light joints or compensate friction).

**Actuator limits** (`safety.saturate`). Drake clamps the actuation input to the effort limits;
the controller saturates first, gracefully (the task part of the torque scaled by the largest
s <= 1 that fits, so velocity and force commands keep their direction), and freezes its integrals
while saturated. Without the freeze the force integral winds up during the 0.7 s at the limit and
the force overshoots for 0.3 s after the command comes back within reach (the reference row).

**Singularities** (`safety.bounded_solve`, `safety.bounded_task_inertia`). Where
sigma_min(J) < 0.05 and the exact inverse would command more than 50 rad/s^2 of joint
acceleration, the inverse of J (or of J M^-1 J^T for a redundant arm) is damped just enough to
meet that bound (the trust-region form of damped least squares), with a
`KinematicSingularityWarning`. A threshold on sigma_min alone would also damp consistent
crossings: the crank task's UR5e crosses its wrist singularity (sigma_min = 6e-4 at t = 2.3 s)
with under 20 rad/s^2, and damping it there raised the crank's force error from 0.2 % to
2-2.7 %. At the Euler chart's singularity the typed `ChartSingularityError` is raised
(tests/test_reliability.py checks both on the UR5e).

**Bad configuration.** Every public constructor and `build_scenario` check their input; the
list is `reliability.BAD_CONFIGURATIONS` (each entry with its error type and message), and
`tests/test_reliability.py` runs each.
"""


def markdown_table(figures):
    rows = [HEADER, ["---"] * len(HEADER)] + [figure.row() for figure in figures]
    return "\n".join("| " + " | ".join(str(cell).replace("|", "\\|") for cell in row) + " |" for row in rows)


def plot_contact_loss(figures, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trace = next(f.details["trace"] for f in figures if "trace" in f.details)
    t = trace["t"]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
    top.plot(t, -trace["force"], label="pressing force -F (N)")
    top.axhline(10.0, color="k", lw=0.7, ls="--", label="|F_d|")
    top.axhline(30.0, color="r", lw=0.7, ls=":", label="3 |F_d|")
    top.set_ylabel("N")
    top.legend(loc="upper right", fontsize=8)
    bottom.plot(t, trace["constraint"] * 1e3, label="C (mm): pad centre above its nominal height")
    bottom.step(t, trace["phase"], where="post", label="supervisor phase (1 approach, 2 contact)")
    bottom.set_xlabel("t (s)")
    bottom.legend(loc="upper left", fontsize=8)
    fig.suptitle("window washing: the window moves up 5 mm in 10 ms at t = 0.3 s", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def update_results_page(table):
    """Replace the table between the markers of docs/results.md (the measured results page)."""
    page = ROOT / "docs" / "results.md"
    text = page.read_text()
    if START not in text or END not in text:
        raise SystemExit(f"docs/results.md has no {START} ... {END} markers")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    page.write_text(f"{head}{START}\n{table}\n{END}{tail}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="the test horizons and no reference runs")
    parser.add_argument("--no-table", action="store_true", help="do not touch docs/results.md")
    arguments = parser.parse_args(argv)
    cases = reliability.CASES + ([] if arguments.quick else reliability.SCRIPT_ONLY_CASES)
    figures, timings = [], {}
    start = time.perf_counter()
    for case in cases:
        case_start = time.perf_counter()
        new = case(quick=arguments.quick)
        timings[case.__name__] = time.perf_counter() - case_start
        figures += new
        for figure in new:
            print(" | ".join(figure.row()), flush=True)
    wall = time.perf_counter() - start
    known, new_failures, fixed = reliability.split_failures(figures)
    references = sum(figure.passed is None for figure in figures)
    passed = len(figures) - len(known) - len(new_failures) - references
    table = markdown_table(figures)
    results_table = markdown_table([figure for figure in figures if figure.passed is not None])
    plot_contact_loss(figures, DOCS / "figures" / "reliability_contact_loss.png")
    environment = f"Python {platform.python_version()}, {platform.machine()}"
    report = [
        "# Reliability: faults injected and survived, measured",
        "",
        f"Generated by `python docs/reliability.py{' --quick' if arguments.quick else ''}` ({environment}; "
        f"{'under a minute' if arguments.quick else '1 to 2.5 minutes'} on 2 cores, the time per case on standard "
        "output). Every row is one measured figure of one closed-loop simulation (1 kHz SAP plant and "
        "controller, hydroelastic pad) or, for the last row, of the input checks; `reference` rows show an "
        "unprotected configuration for comparison and have no pass/fail. Tests: `tests/test_reliability.py` "
        "runs the same cases with shorter horizons (`--quick`).",
        "",
        table,
        "",
        f"**{passed} pass, {len(known)} known failure{'' if len(known) == 1 else 's'} (below), "
        f"{len(new_failures)} new failure{'' if len(new_failures) == 1 else 's'}, {references} reference.**",
        "",
        *[f"- Known failure, {f.fault} ({f.magnitude}), {f.figure}: {reliability.KNOWN_FAILURES[f.key()]}."
          for f in known],
        "",
        "![contact loss](figures/reliability_contact_loss.png)",
        "",
        "*The window moves up 5 mm in 10 ms at t = 0.3 s: the force drops, the supervisor declares the "
        "contact lost after 10 ms, the guarded move carries the pad up at 0.02 m/s and the hybrid law "
        "resumes on contact.*",
        "",
        EXPLANATIONS.rstrip("\n"),
    ]
    (DOCS / "reliability.md").write_text("\n".join(report) + "\n")

    def serializable(details):
        return {key: value for key, value in details.items() if key != "trace"}

    (DOCS / "reliability.json").write_text(json.dumps(significant(
        {"environment": environment, "quick": arguments.quick,
         "figures": [dict(case=f.case, fault=f.fault, magnitude=f.magnitude, figure=f.figure, value=f.value,
                          limit=f.limit, unit=f.unit, criterion=f.criterion, passed=f.passed,
                          details=serializable(f.details)) for f in figures]}),
        indent=1, default=lambda o: o.name if hasattr(o, "name") else str(o)) + "\n")
    if not arguments.no_table:
        update_results_page(results_table)
    for name, seconds in timings.items():
        print(f"  {name}: {seconds:.1f} s")
    for figure in fixed:
        print(f"passes now, remove it from KNOWN_FAILURES: {' | '.join(figure.row())}")
    for figure in new_failures:
        print(f"NEW FAILURE (not in KNOWN_FAILURES): {' | '.join(figure.row())}")
    print(f"{len(figures)} figures: {passed} pass, {len(known)} known failure(s), {len(new_failures)} new "
          f"failure(s), {references} reference; {wall:.0f} s")
    return reliability.exit_code(figures)


if __name__ == "__main__":
    sys.exit(main())
