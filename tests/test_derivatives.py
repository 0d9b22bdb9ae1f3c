"""The linearization's Jacobian check: AutoDiffXd against central differences, and the fallback.

On the window task the two agree and AutoDiffXd is used. With the ball pad pressing a ``Box``
at a symmetric pose (pad centred on the face, pointing straight down), Drake 1.51's AutoDiffXd
derivative of the hydroelastic force is wrong (docs/drake_notes.md): the check catches it, the
linearization uses central differences and says so.
"""

import warnings

import numpy as np
import pytest

from pydrake.geometry import Box
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.analysis.derivatives import (JACOBIAN_TOLERANCE, DerivativeMismatchWarning, JacobianCheck,
                                               checked_state_jacobian, column_errors)
from drake_hybrid.analysis.linearization import equilibrium_config, linearize_continuous
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.tasks.builtin.robots import UR5E_SEED, add_ur5e_with_pad
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.registry import get_task, register_task

BLOCK_TOP = np.array([0.45, 0.1, 0.1])        # centre of the block's top face (m)
BLOCK_TILT = RotationMatrix.MakeYRotation(0.35)  # a tilted plane
NORMAL = BLOCK_TILT.col(2)


def ur5e_on_a_block():
    """The UR5e's pad pressing 10 N on the top face of a tilted Box, its centre over the face's
    centre, pointing along the face's normal."""
    def add_block(plant):
        return add_rigid_workpiece(plant, Box(0.4, 0.4, 0.1), RigidTransform(BLOCK_TILT, BLOCK_TOP - 0.05 * NORMAL),
                                   name="block")

    chart = PoseChart()
    plane = surface_constraint(chart, lambda p: sum(NORMAL[i] * (p[i] - BLOCK_TOP[i]) for i in range(3)) - 0.02,
                               name="block top", normal_rows=False)
    space = ConstraintSpace(plane, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0), name="in-plane"))
    start = RigidTransform(BLOCK_TILT @ RotationMatrix.MakeXRotation(np.pi), BLOCK_TOP + 0.02 * NORMAL)
    task = register_task(CustomTask("test-ur5e-block", add_robot=add_ur5e_with_pad, add_workpiece=add_block,
                                    constraint_space=space, start_pose=start, joint_guess=UR5E_SEED))
    return task.default_config(desired_velocity=[0.0] * 5, desired_force=[10.0],
                               gains=HybridGains(velocity=[10.0], force_proportional=[0.5], force_integral=[15.0]))


def test_column_errors_are_relative_to_the_column_and_ignore_rounding_columns():
    reference = np.array([[1000.0, 1e-9, 2.0], [10.0, 0.0, 1.0]])
    autodiff = reference + np.array([[1.0, 3e-9, 0.0], [0.0, 0.0, 1.0]])
    relative, absolute = column_errors(autodiff, reference)
    np.testing.assert_allclose(absolute, [1.0, 3e-9, 1.0])
    # column 1 is below 1e-8 max |A|: scaled by 1e-5, not by itself
    np.testing.assert_allclose(relative, [1.0 / 1001.0, 3e-9 / 1e-5, 1.0 / 2.0])


def test_the_check_summary_says_what_is_compared_which_figure_is_judged_and_which_A_is_used():
    dut = JacobianCheck(max_relative_error=2.3e-5, max_absolute_error=0.12, worst_column=2, worst_state="plant q[2]",
                        tolerance=1e-3, epsilon=1e-5, used="autodiff", evaluations=12, largest_entry=4.8e3)
    assert dut.summary() == (
        "Jacobian check (AutoDiffXd vs central differences, step 1e-05): agree; the columns of AutoDiffXd's A "
        "differ from central differences by at most 2.3e-05 of the column's size (tolerance 0.001; largest in "
        "column plant q[2]); eigenvalues from AutoDiffXd's A")
    dut.max_relative_error, dut.used = 1.0, "autodiff with 2 column(s) from central differences"
    dut.replaced = ["plant q[0]", "plant q[2]"]
    assert ": DISAGREE;" in dut.summary()
    assert "; replaced by central differences: plant q[0], plant q[2] (Drake's AutoDiffXd" in dut.summary()
    assert dut.summary().endswith("eigenvalues from AutoDiffXd's A with 2 column(s) from central differences")
    assert dut.as_dict()["largest_entry"] == 4.8e3


def test_the_window_linearization_agrees_with_central_differences_and_uses_autodiff():
    with warnings.catch_warnings():
        warnings.simplefilter("error", DerivativeMismatchWarning)
        dut = linearize_continuous(get_task("window-washing").default_config())
    check = dut.jacobian_check
    assert check.used == "autodiff" and check.agrees
    # Measured 2.3e-5 (the wrist column: rounding in the contact surface); 40 times below the tolerance.
    assert check.max_relative_error < 1e-4 < JACOBIAN_TOLERANCE
    assert check.evaluations == 2 * dut.A.shape[0]
    assert "): agree;" in check.summary() and "eigenvalues from AutoDiffXd's A" in check.summary()
    assert dut.match.matched


def test_a_box_workpiece_gets_the_central_difference_jacobian_with_a_warning():
    config = ur5e_on_a_block()
    # The paper's form: the default law cancels the measured F_v (control.law.tangential_compensation),
    # and with it the wrong tangential derivative's effect, which this test needs to see.
    config.compensate_tangential_force = False
    with pytest.warns(DerivativeMismatchWarning, match="disagrees with central differences"):
        dut = linearize_continuous(config)
    check = dut.jacobian_check
    assert "from central differences" in check.used and check.replaced and not check.agrees
    assert check.max_relative_error > 0.1                       # measured 1.0: not rounding
    assert "DISAGREE" in check.summary() and check.as_dict()["replaced"] == check.replaced
    # With the central-difference A the closed loop matches its design and nothing is unstable
    # (largest real part measured 2.8e-5 1/s) ...
    assert dut.match.matched and dut.match.unstable_extra.size == 0
    assert dut.eigenvalues.real.max() < 1e-3
    # ... while AutoDiffXd's A, used blindly, shows a mode that does not exist (measured +0.123 1/s).
    blind = linearize_continuous(config, jacobian_tolerance=np.inf)
    assert blind.jacobian_check.used == "autodiff" and not blind.match.matched
    assert blind.eigenvalues.real.max() > 0.05


def test_checked_state_jacobian_returns_the_autodiff_matrix_only_when_it_agrees():
    """The fallback itself, on the window's closed loop: a corrupted AutoDiffXd A is replaced."""
    config = get_task("window-washing").default_config()
    dut = linearize_continuous(config)
    scenario_A = dut.A                                     # AutoDiffXd's (the check agreed)
    from_check = _window_point(config)
    A, check = checked_state_jacobian(*from_check, scenario_A)
    assert check.used == "autodiff"
    np.testing.assert_array_equal(A, scenario_A)
    corrupted = scenario_A.copy()
    corrupted[4, 0] += 0.01 * np.abs(scenario_A[:, 0]).max()
    with pytest.warns(DerivativeMismatchWarning, match="column plant joint1_q"):
        A, check = checked_state_jacobian(*from_check, corrupted)
    assert check.replaced == ["plant joint1_q"] and check.worst_state == "plant joint1_q"
    assert check.used == "autodiff with 1 column(s) from central differences"
    np.testing.assert_array_equal(np.delete(A, 0, axis=1), np.delete(scenario_A, 0, axis=1))
    np.testing.assert_allclose(A[:, 0], scenario_A[:, 0], rtol=0, atol=1e-4 * np.abs(scenario_A[:, 0]).max())


def test_a_step_too_coarse_for_a_stiff_pad_is_not_taken_for_a_wrong_derivative():
    """A 1 GPa pad presses micrometres deep: the 1e-5 step's truncation error exceeds the tolerance
    (measured 0.32 % in the joint1 column), a tenth of it agrees with AutoDiffXd, which is kept."""
    config = get_task("window-washing").default_config()
    config.contact.pad_modulus = 1e9
    with warnings.catch_warnings():
        warnings.simplefilter("error", DerivativeMismatchWarning)
        dut = linearize_continuous(config)
    check = dut.jacobian_check
    assert check.used == "autodiff" and check.agrees and check.replaced == [] and check.unresolved == []
    assert check.evaluations > 2 * dut.A.shape[0]               # the finer step was needed


def _window_point(config):
    scenario = build_scenario(equilibrium_config(config), with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    return scenario.diagram, context
