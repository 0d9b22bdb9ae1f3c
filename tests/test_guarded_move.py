"""The guarded move's integral action: it reaches the contact threshold whatever the contact's damping
and the arm's task inertia (control.law.guarded_acceleration, supervision.ContactSupervisor's
approach reference).

A velocity servo alone, C-ddot = -K_a (C-dot - s n_C), stalls against the surface at the pressing
force Lambda_f K_a s (Lambda_f: the task inertia along the force rows). With SAP's lighter pair
relaxation (pad 0.01 s, workpiece 0: docs/drake_notes.md) the UR5e's stalled at 1.45 N, below its
contact threshold of 3 N, and never declared contact. The servo to the reference C_r moving at s n_C
has no such cap: against the surface its force rises at Lambda_f K_a^2 s per second.
"""

import numpy as np
import pytest
import reliability_cases as reliability

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.tasks.registry import get_task


def lighter_pair(config):
    """SAP's pair relaxation time 0.01 s: the pad's 0.01 s, a rigid workpiece's 0."""
    config.contact.relaxation_time = 0.01
    config.contact.workpiece_relaxation_time = 0.0
    return config


def force_row_inertia(result):
    """Lambda_f = (E_f J M^-1 J^T E_f^T)^-1 at the start (the force rows' task inertia, m x m)."""
    scenario = result.scenario
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, result.log["q"][0])
    task = scenario.controller.kinematics.evaluate(context)
    values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
    A = values.force_projection @ task.jacobian
    return np.linalg.inv(A @ np.linalg.solve(plant.CalcMassMatrix(context), A.T))


@pytest.mark.slow                # a closed-loop simulation of the UR5e
def test_ur5e_reaches_contact_on_the_sphere_with_the_lighter_pair_within_the_documented_bound():
    """The case that stalled: reliability_cases.case_sphere_approach with the pair at 0.01 s."""
    config = get_task("sphere-polishing").default_config()
    config.duration = 0.4
    config.start.force_integral = []
    config.start.in_contact = False
    config.start.gap = 0.005
    result = simulate(lighter_pair(config))
    supervision = config.supervision
    contact = reliability.first_time(result.log, ContactPhase.CONTACT)
    assert contact <= config.start.gap / supervision.approach_speed + 3.0 / supervision.approach_gain
    assert reliability.peak_pressing_force(result) <= 3.0 * 10.0


@pytest.mark.slow                # a closed-loop simulation of the window task
def test_the_stall_force_of_the_velocity_servo_no_longer_caps_the_pressing_force():
    """Window task, lighter pair, contact threshold at |F_d| = 10 N: far above what the servo's
    proportional part can press with when stalled (2 Lambda_f K_a s, checked below), so only the
    integral action reaches it: at Lambda_f K_a^2 s per second after the pad stops, i.e. within
    (threshold - 2 Lambda_f K_a s) / (Lambda_f K_a^2 s) of the arrival at gap / s (+ 3 / K_a for the
    transients)."""
    config = reliability.window_config(1.0)
    config.start.in_contact = False
    config.supervision.contact_threshold = 1.0
    result = simulate(lighter_pair(config))
    supervision, gap = config.supervision, config.start.gap
    s, K_a, threshold = supervision.approach_speed, supervision.approach_gain, 10.0
    Lambda_f = float(force_row_inertia(result)[0, 0])
    assert 2.0 * Lambda_f * K_a * s < 0.5 * threshold                # the proportional part alone stalls below it
    contact = reliability.first_time(result.log, ContactPhase.CONTACT)
    ramp = (threshold - 2.0 * Lambda_f * K_a * s) / (Lambda_f * K_a ** 2 * s)
    print(f"Lambda_f {Lambda_f:.3f} kg, contact at {contact:.3f} s, bound {gap / s + 3.0 / K_a + ramp:.3f} s")
    assert contact <= gap / s + 3.0 / K_a + ramp
