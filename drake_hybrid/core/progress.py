"""Setup stages with their times, printed as they happen (the first output within a second).

``Stages(enabled=True)`` prints ``label ... 1.2 s`` for each ``with stages("label"):`` block to
standard error (standard output stays for results); ``Stages(enabled=False)``, the default
everywhere, prints nothing::

    stages = Stages()
    with stages("building the diagram"):
        scenario = build_scenario(config)
"""

import sys
import time
from contextlib import contextmanager
from typing import Any, Callable, ContextManager

# What the library's functions take as ``stages``: a Stages, or any callable label -> context manager.
StagesLike = Callable[[str], ContextManager[Any]]


class Stages:
    """Prints one line per setup stage with its wall time (or nothing when not ``enabled``)."""

    def __init__(self, enabled=True, stream=None, prefix=""):
        self.enabled = bool(enabled)
        self.stream = stream
        self.prefix = prefix
        self.times = {}            # label -> seconds, also when not enabled

    def _write(self, text, end="\n"):
        if self.enabled:
            print(text, end=end, file=self.stream or sys.stderr, flush=True)

    @contextmanager
    def __call__(self, label):
        self._write(f"{self.prefix}{label} ...", end="")
        start = time.perf_counter()
        try:
            yield
        except BaseException:
            self._write(" failed")
            raise
        self.times[label] = time.perf_counter() - start
        self._write(f" {self.times[label]:.1f} s")


def quiet() -> Stages:
    """A Stages that prints nothing (the default of the library's functions)."""
    return Stages(enabled=False)
