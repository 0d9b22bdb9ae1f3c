"""What every figure of the package shares: pyplot on a backend that needs no display (Agg, unless a
headless one such as Jupyter's inline backend is already set), and log axes that span the measured
values without drawing a numeric floor as data.
"""

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

# Backends that need no display: kept as they are (Jupyter's inline backend reports "inline" or its
# module name, depending on the matplotlib version).
_HEADLESS_BACKENDS = ("agg", "pdf", "svg", "ps", "cairo", "inline", "module://matplotlib_inline.backend_inline",
                      "widget", "ipympl", "module://ipympl.backend_nbagg", "nbagg")


def _pyplot():
    """pyplot on a backend that needs no display (Agg unless a headless one is already set)."""
    if matplotlib.get_backend().lower() not in _HEADLESS_BACKENDS:
        plt.switch_backend("Agg")
    return plt


def _positive(values):
    """``values`` with zeros (and negative rounding) masked as NaN: a log axis shows no numeric floor."""
    values = np.asarray(values, dtype=float)
    return np.where(values > 0, values, np.nan)


_LOG_DECADES = 8          # a log axis of measured values spans at most this many decades below their max


def _measured_on_log(values, top):
    """``values`` (>= 0) to draw on a log axis whose largest measured value is ``top``: zeros and the
    numeric floor (below ``top`` / 10^(``_LOG_DECADES`` + 1), e.g. a solved start's 1e-15) masked as
    NaN, so that no floor is drawn as data."""
    values = _positive(values)
    return np.where(values >= top * 10.0 ** -(_LOG_DECADES + 1), values, np.nan) if np.isfinite(top) else values


def _set_log_limits(ax, measured):
    """Limits of a log axis: the measured values (``_measured_on_log``), at most ``_LOG_DECADES`` decades."""
    measured = np.asarray(measured, dtype=float)
    if np.isfinite(measured).any():
        top, bottom = np.nanmax(measured), np.nanmin(measured)
        ax.set_ylim(max(bottom, 10.0 ** -_LOG_DECADES * top) / 2, 2 * top)
