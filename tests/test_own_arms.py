"""Issue 12's acceptance figures on arms the package does not ship (tests/own_arm_cases.py): nine of
the 27 (arm, shape, mode) cases, a Latin square, so every arm meets every shape and every mode and
every shape every mode. docs/own_arms.py runs all 27 and writes docs/own_arms.md.

Per case: errors after five design time constants <= 2 % (velocity and force, % of the command),
every designed eigenvalue within 5 % of its linearized partner, no real part above 0.01 1/s, and
the Jacobian check in the linearization's output. Nothing is tuned per robot but its frames.

Every case's linearized eigenvalues are also checked against the prediction (analysis.environment):
in impedance-force mode the design with the contact's own stiffness and damping along the rows,
measured by central differences of the wrench sensor; elsewhere the design itself. An impedance-force
run's velocity errors are checked against those of the designed impedance (3.2-11) driven by the
run's measured F_v (within 2 % of the command; measured 0.01-0.07 %, and 0.08-0.09 % with Drake's
0.2 s contact pair, whose drag was 0.24 N).

Known misses, kept visible (each fails the run the day it is met, so KNOWN is kept true). The
tessellated contact is stiff along the surface (docs/drake_notes.md):
- impedance-force on the 5 cm cylinder: the unit-mass impedance yields to it, as designed: its pair
  (-3, -7) moves 21.7-21.8 % from the gains' design (4.3-4.4 % on the sphere), within 0.5 % of the
  prediction with the contact's measured stiffness (+2.6 N/m) and damping (-0.2 N s/m).
  The simulation's SAP contact drags about nine times harder than the linearization's continuous
  twin (the run's drag, -1.84 to -1.91 N s/m on every curved case): closed through it the pair would
  sit near (-2.2, -9.7), on the sphere too (docs/drake_notes.md, "The simulated contact's drag").
  With the impedance mass cases.HEAVY_IMPEDANCE_MASS = 10 (gains.impedance_mass; the same roots,
  ten times less yielding) the cylinder meets every figure on all three arms
  (test_a_heavier_impedance_meets_every_figure_on_the_cylinder; docs/own_arms.md, second table).
Impedance-force on the 5 cm cylinder and sphere used to miss its velocity errors (6.6-6.9 %): SAP
damped each contact face along its normal with Drake's 0.2 s pair relaxation, which dragged the pad
0.24 N although mu = 0. The default pair is now 0.03 s (station.contact.ContactConfig): 0.04 N.
Position-force on the sphere (and the xArm7's cylinder) used to miss its pair (-3, -7) by 7.6-12 %:
the law split the wrench, which the linearization's 200 Hz low-pass delays, with the current E(x).
It now splits it where it was measured (control.law.measured_forces), within 0.71 %.
"""

import logging

import own_arm_cases as cases
import pytest

logging.getLogger("drake").setLevel(logging.ERROR)

# (shape, mode): the figures of issue 12 that the case is known to miss (module docstring)
KNOWN = {
    ("cylinder", "impedance-force"): {"eigenvalue_error"},
}
LIMITS = {"velocity_error_percent": cases.MAX_ERROR_PERCENT, "force_error_percent": cases.MAX_ERROR_PERCENT,
          "eigenvalue_error": cases.EIGENVALUE_TOLERANCE}


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("meshes")


@pytest.mark.slow
@pytest.mark.parametrize("arm, shape, mode", cases.latin_square(), ids=["-".join(case) for case in cases.latin_square()])
def test_own_arm_on_own_surface(arm, shape, mode, cache):
    figures = cases.run(arm, shape, mode, cache)
    assert "Jacobian check" in figures["jacobian_check"]
    assert figures["max_real_part"] <= cases.MAX_REAL_PART, figures
    assert figures["eigenvalue_error_predicted"] <= cases.EIGENVALUE_TOLERANCE, figures
    if mode == "impedance-force":         # the run realizes the designed impedance, driven by its measured F_v
        assert figures["velocity_error_against_impedance_percent"] <= cases.MAX_ERROR_PERCENT, figures
    # mu = 0: the flat pad slides without drag; on a curved workpiece the contact's dissipation along
    # the face normals drags it (measured -1.84 to -1.91 N s/m on every curved case, 0.000 on the plate)
    if shape == "plane":
        assert abs(figures["run_drag"]) < 0.01, figures
    else:
        assert figures["run_drag"] < -0.5, figures
    known = KNOWN.get((shape, mode), set())
    for name, limit in LIMITS.items():
        if name in known:
            assert figures[name] > limit, f"{name} is now met ({figures[name]:.4g} <= {limit}): update KNOWN"
        else:
            assert figures[name] <= limit, figures


def test_the_latin_square_covers_every_pair():
    square = cases.latin_square()
    assert len(square) == 9
    for a, b in ((0, 1), (0, 2), (1, 2)):
        assert len({(case[a], case[b]) for case in square}) == 9


@pytest.mark.slow
def test_the_xarm7_impedance_answers_a_force_through_its_damped_wrist(cache):
    """The xArm7's wrist (joint7, b h / M = 11.8 at 1 ms) answers a force within a step through
    (M + h B)^-1, and K_0 is built from J (M + h B)^-1 J^T (control.damping). Impedance-force on the
    5 cm sphere, with the contact's dissipation that barely drags the pad (relaxation time 0.01 s on
    the pad, 0 on the workpiece: SAP's pair at 0.01 s, lighter than the default 0.03 s): velocity
    error after five time constants measured 0.64 % (2.07 % with K_0 from J M^-1 J^T, its rows wy and
    wz off by 4.4e-3 and 6.1e-3 rad/s; now below 5e-5)."""
    cfg = cases.config(cases.task("xarm7", "sphere", cache), "impedance-force")
    cfg.contact.relaxation_time, cfg.contact.workpiece_relaxation_time = 0.01, 0.0
    summary = cases.simulate(cfg).summary
    assert summary.max_velocity_error_percent_after_5_time_constants < 1.0, summary
    assert summary.max_force_error_percent_after_5_time_constants < 1.0, summary
    rotation = [row.max_error_after_5_time_constants for row in summary.velocity_rows[2:]]   # wx, wy, wz
    assert max(rotation) < 1e-3, rotation


@pytest.mark.slow
@pytest.mark.parametrize("arm", list(cases.ARMS))
def test_a_heavier_impedance_meets_every_figure_on_the_cylinder(arm, cache):
    """The figure the 5 cm cylinder misses (KNOWN) is the unit-mass impedance yielding to the contact's
    own stiffness and damping. With the impedance mass cases.HEAVY_IMPEDANCE_MASS = 10 (one value for every
    arm and row; the roots K_v and K_p design are unchanged) they move the designed roots about ten times
    less, and the case meets every figure: eigenvalues measured within 2.4-2.6 % of the gains' design
    (21.7-21.8 % at the paper's unit mass) and 0.3-0.4 % of the prediction; the run's steady drag
    (-1.9 N s/m, the simulated SAP contact) over M_d moves the design by 4.6 % (38.9 % at unit mass)."""
    figures = cases.run(arm, "cylinder", "impedance-force", cache, impedance_mass=cases.HEAVY_IMPEDANCE_MASS)
    assert figures["passed"], figures
    assert "Jacobian check" in figures["jacobian_check"]
    assert figures["eigenvalue_error_predicted"] <= 0.01, figures
    assert figures["velocity_error_against_impedance_percent"] <= cases.MAX_ERROR_PERCENT, figures
    assert figures["run_drag"] < -0.5 and figures["eigenvalue_error_with_run_drag"] <= cases.EIGENVALUE_TOLERANCE
