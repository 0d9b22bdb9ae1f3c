"""The contact phase: the contact supervisor's state, which the controller's law reads."""

import enum


class ContactPhase(enum.IntEnum):
    """Phases of ``supervision.ContactSupervisor``; the value travels on its ``contact_phase`` port.

    In every phase but CONTACT the controller runs the guarded move on the force-controlled rows
    of C: C-ddot = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r) with n_C the pressing direction in C's
    coordinates, s the approach speed (APPROACH) or 0 (TARE, HOLD) and C_r the supervisor's approach
    reference (moving at s n_C in APPROACH); no force feedback, the controller's integrals frozen.
    """

    TARE = 0        # in free space, holding still while the wrench conditioner measures the sensor's bias
    APPROACH = 1    # guarded move toward the surface at the approach speed
    CONTACT = 2     # the hybrid law of the paper
    HOLD = 3        # no surface within the allowed travel: holding still, waiting for a force
