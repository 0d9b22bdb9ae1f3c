"""What every law system of ``control`` shares around its law (``HybridController`` and the
baselines of ``control.baselines``): the accessors of its plant, gains and state layout, and the
reading of its integrals from continuous or discrete state.

A law system sets ``_plant``, ``_gains``, ``_state_port``, ``_wrench_port``, ``_diagnostic_slices``,
``control_period`` and ``_integrated_size``; with a control period its first discrete state group
is [integrals; held actuation], otherwise the integrals are its continuous state.
"""


class MultibodyForcesHolder:
    """A MultibodyForces in a cache entry (a Python object, so the cache holds it by reference): a
    law system's per-context scratch for the plant's force elements."""

    __slots__ = ("forces",)

    def __init__(self, forces):
        self.forces = forces


class LawSystemParts:
    """Mixin of the accessors and the integral-state reading every law system shares."""

    def plant(self):
        """The controller's own plant (of this system's scalar type)."""
        return self._plant

    def validated_gains(self):
        """The gains as matrices (control.gains.ValidatedGains, or the baseline's)."""
        return self._gains

    def get_estimated_state_input_port(self):
        return self._state_port

    def get_measured_wrench_input_port(self):
        return self._wrench_port

    def diagnostic_slices(self):
        """{name: slice} of each diagnostic in the ``diagnostics`` output."""
        return dict(self._diagnostic_slices)

    def _integrals(self, context):
        """The integral states: continuous, or the first ``_integrated_size`` discrete entries."""
        if self.control_period is None:
            return context.get_continuous_state_vector().CopyToVector()
        return context.get_discrete_state(0).CopyToVector()[:self._integrated_size]
