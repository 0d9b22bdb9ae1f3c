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


def declare_periodic_update(system, period, offset, handler):
    """``system.DeclarePeriodicDiscreteUpdateEvent(period, offset, handler)``, the handler also kept as
    ``system.periodic_update_handler``: what Drake calls at the system's periodic update, given the
    context and a copy of its discrete state to write. A runner that ticks the system itself
    (hardware.tick.ControllerTick) calls it directly, without Drake's event dispatch (a few
    microseconds a system, a tenth of a hardware tick). A system with two such events keeps None."""
    system.DeclarePeriodicDiscreteUpdateEvent(period, offset, handler)
    system.periodic_update_handler = None if hasattr(system, "periodic_update_handler") else handler
