"""What every law system of ``control`` shares around its law (``HybridController`` and the
baselines of ``control.baselines``): the accessors of its plant, gains and state layout, and the
reading of its integrals from continuous or discrete state.

A law system sets ``_plant``, ``_gains``, ``_state_port``, ``_wrench_port``, ``_diagnostic_slices``,
``control_period`` and ``_integrated_size``; with a control period its first discrete state group
is [integrals; held actuation], otherwise the integrals are its continuous state.

Its diagnostic outputs (``declare_diagnostic_outputs``) never read as success for a measured wrench
that was invalid (a NaN or inf entry: a sensor dropout): the law then takes F = F_d so that it holds
the force integral, but the ports that report what the wrench gives (F, e_f, F_v) read NaN for that
evaluation, and ``wrench_valid`` reads 0 (1 when valid).
"""

import numpy as np

# The diagnostics in the order of the ``diagnostics`` layout; the ones the measured wrench gives read
# NaN when it was invalid.
DIAGNOSTICS = ("velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
               "tangential_force", "wrench_valid")
FROM_THE_WRENCH = ("force_error", "force", "tangential_force")


def reported_diagnostic(solution, name):
    """The diagnostic ``name`` of a law's solution as its output port reports it (see the module
    docstring): NaN for F, e_f and F_v after an invalid wrench; ``wrench_valid`` as [1.] or [0.]."""
    if name == "wrench_valid":
        return np.array([1.0 if solution.wrench_valid else 0.0])
    values = getattr(solution, name)
    if name in FROM_THE_WRENCH and not solution.wrench_valid:
        return np.full(len(values), np.nan)
    return values


def reported_diagnostics_vector(solution):
    """Every diagnostic, as reported, concatenated in the ``diagnostics`` layout."""
    return np.concatenate([np.asarray(reported_diagnostic(solution, name)) for name in DIAGNOSTICS])


def declare_diagnostic_outputs(system, velocity_size, force_size, solution_of, prerequisites):
    """Declare the diagnostic output ports of a law system (``DIAGNOSTICS``, each from
    ``solution_of(context)`` as ``reported_diagnostic`` reports it) and set its ``_diagnostic_slices``;
    returns the total size."""
    k, m = velocity_size, force_size
    sizes = {"velocity_error": k, "force_error": m, "constraint_value": m, "projected_velocity": k, "force": m,
             "tangential_force": k, "wrench_valid": 1}
    system._diagnostic_slices, start = {}, 0
    for name in DIAGNOSTICS:
        def calc(context, output, name=name):
            output.SetFromVector(reported_diagnostic(solution_of(context), name))
        system.DeclareVectorOutputPort(name, sizes[name], calc, prerequisites_of_calc=prerequisites)
        system._diagnostic_slices[name] = slice(start, start + sizes[name])
        start += sizes[name]
    return start


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
