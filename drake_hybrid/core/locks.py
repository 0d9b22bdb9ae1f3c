"""Lock files held by a process: whether their holder still runs (a lock whose process died is
taken over). Used by a sweep's output folder (``experiments.sweep.SweepLock``) and the compiled
law's background job (``control.fast_compile``)."""

import os


def process_alive(pid):
    """True if a process with id ``pid`` runs on this machine (one of another user's counts too)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
