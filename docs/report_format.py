"""Figures as the docs scripts write them: rounded to what they mean, so that a rerun on an
unchanged tree rewrites its files byte for byte (``git status`` stays clean).

    from report_format import significant
    path.write_text(json.dumps(significant(results), indent=1) + "\\n")

Used by ``docs/make_baselines.py`` and ``docs/reliability.py`` (they run as scripts, so this folder is
on their path); tested in ``tests/test_report_format.py``.
"""

import math

import numpy as np

DIGITS = 4            # significant figures kept: the tables print 3 or 4
ZERO = 1e-9           # |x| below this is a numerical zero (an eigenvalue's real part of 1e-15 1/s, ...)


def significant(value, digits=DIGITS, zero=ZERO):
    """``value`` with every float rounded to ``digits`` significant figures and every float of
    magnitude below ``zero`` written as 0.0, through dicts, lists, tuples and NumPy arrays; ints,
    bools, strings and None unchanged, nan and inf kept."""
    if isinstance(value, dict):
        return {key: significant(item, digits, zero) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [significant(item, digits, zero) for item in value]
    if isinstance(value, np.ndarray):
        return significant(value.tolist(), digits, zero)
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if not math.isfinite(value):
            return value
        if abs(value) < zero:
            return 0.0
        return float(f"{value:.{digits - 1}e}")
    return value
