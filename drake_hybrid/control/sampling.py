"""When the sampled systems tick.

Every sampled part of the closed loop (the controller, the wrench conditioner, the sensor-fault
injector, the contact supervisor) ticks a fraction ``SAMPLE_LEAD`` of its period before each
multiple of the period: late enough to read the plant's newest state, early enough for a discrete
plant stepping at the multiples of the period to apply the new torque at once (a zero-order hold
without computation delay; ``HybridController``'s docstring gives the reason in full).
"""

SAMPLE_LEAD = 1e-6


def tick_offset(period, lead=True):
    """The offset of the periodic event of a system sampled with ``period``: k h - SAMPLE_LEAD h
    (``lead``) or k h."""
    return float(period) * (1.0 - SAMPLE_LEAD) if lead else 0.0
