"""The paper's stability verdict on a scenario config (rigid contact, an exact model, a continuous
controller): its designed eigenvalues in the open left half-plane. A sweep's stability map draws
its boundary over two parameters (``theory_on_plane``) beside the simulated and linearized verdicts.
"""

import copy

import numpy as np

from drake_hybrid.analysis.design import predicted_eigenvalues
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.errors import GainError
from drake_hybrid.experiments.config_paths import set_config_value
from drake_hybrid.tasks.registry import get_task


def rigid_contact_theory_stable(config, sizes=None):
    """The paper's verdict on ``config``: with rigid contact, an exact model and a continuous
    controller the errors obey (3.1-14), (3.1-15) (Remark 3, (3.2-11) in the other modes), so the
    loop is stable iff the designed eigenvalues (-eig(K_v) or the roots of s^2 + K_v s + K_p, and
    eig(-(I + K_fp)^-1 K_fi)) are in the open left half-plane. None when the gains are outside the
    law's admissible set (GainError). The theory sees no contact stiffness and no sampling.
    ``sizes``: (d - m, m) if known (saves building the task's constraint)."""
    velocity_size, force_size = sizes or constraint_sizes(config)
    mode = ControlMode.parse(config.mode)
    try:
        gains = config.gains.matrices(velocity_size, force_size, mode)
    except GainError:
        return None
    return bool(np.all(predicted_eigenvalues(gains, mode).designed.real < 0))


def constraint_sizes(config):
    """(d - m, m): the velocity- and force-controlled dimensions of ``config``'s task."""
    space = get_task(config.task).constraint_space(config)
    return space.velocity_size, space.force_size


def theory_on_plane(base_config, x_path, y_path, x_values, y_values, fixed=None):
    """``rigid_contact_theory_stable`` over the (x, y) plane (other fields from ``fixed`` and the base):
    an array (len(y_values) x len(x_values)) of 1.0 (stable), 0.0 (unstable) and nan (not admissible)."""
    sizes = constraint_sizes(base_config)
    verdict = np.full((len(y_values), len(x_values)), np.nan)
    for i, y in enumerate(y_values):
        for j, x in enumerate(x_values):
            config = copy.deepcopy(base_config)
            for path, value in {**(fixed or {}), x_path: x, y_path: y}.items():
                set_config_value(config, path, value)
            stable = rigid_contact_theory_stable(config, sizes)
            verdict[i, j] = np.nan if stable is None else float(stable)
    return verdict
