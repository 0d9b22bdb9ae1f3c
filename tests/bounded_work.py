"""Bounded work, counted instead of timed: what "refused quickly" protects against, without a clock.

A hostile input (a deeply nested or self-referencing YAML file, an expression like 9 ** 9 ** 9) must be
refused before the work it asks for is done: no exponential blow-up, no evaluation of what is refused.
A wall-clock limit says that badly (the suite runs beside other work, and a loaded machine is slow),
so the tests count the Python-level calls a refusal makes (``sys.setprofile``: every Python and C
function call; the same count on any machine, at any load) and check

* that doubling the hostile input at most about doubles the count (``at_most_linear``): no blow-up;
* that the count stays below what a legitimate input of the same kind costs (``calls`` of it).
"""

import sys


def calls(call):
    """How many function calls (Python and C) ``call()`` makes; its exception, if any, is returned
    (the caller checks it) rather than raised."""
    count = 0

    def profile(frame, event, arg):
        nonlocal count
        if event in ("call", "c_call"):
            count += 1

    previous = sys.getprofile()
    sys.setprofile(profile)
    try:
        call()
        raised = None
    except Exception as error:   # noqa: BLE001 -- returned for the caller to check
        raised = error
    finally:
        sys.setprofile(previous)
    return count, raised


def at_most_linear(small, large, factor=2.0, slack=1.25, constant=500):
    """True if ``large`` (the count for an input ``factor`` times the size of ``small``'s) grows at most
    linearly: large <= slack * factor * small + constant."""
    return large <= slack * factor * small + constant
