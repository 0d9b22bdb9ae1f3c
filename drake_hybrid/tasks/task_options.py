"""The built-in tasks' typed options (``--option KEY=VALUE``, ``task_options`` in a config), with the
standard library only.

Each task module (``tasks.registry``) takes its ``Options`` from here, so that the command line lists
every task's options in ``drake-hybrid simulate --help`` without loading Drake (``option_help``);
``Task.options`` reads and checks a config's values against them.
"""

import dataclasses
from dataclasses import dataclass, fields

from drake_hybrid.core.errors import ConfigError

CRANK_START_ANGLE = 4.412                # rad, crank angle alpha at t = 0 (tasks.builtin.crank_turning)


def is_task_file(name):
    """True if ``name`` (a task argument) names a task file (tasks.task_file) rather than a registered task."""
    return str(name).endswith((".yaml", ".yml"))


def choice(default, allowed):
    """A string option whose value must be one of ``allowed``."""
    return dataclasses.field(default=default, metadata={"allowed": tuple(allowed)})


@dataclass
class WindowWashingOptions:
    window_height: float = 1.0          # m, the pane's lower face (the paper's y = 1)
    joints: int = 3                     # 3: the paper's square arm; 4: a redundant arm
    window_lift: float = 0.0            # m the pane moves up (0: welded pane)
    window_lift_time: float = 0.5       # s, when the lift starts
    window_lift_duration: float = 0.01  # s, over how long


@dataclass
class CrankTurningOptions:
    start_angle: float = CRANK_START_ANGLE                      # rad, crank angle alpha at t = 0
    velocity_rows: str = choice("true", ("true", "paper"))      # E_p: true-velocity rows or (3.3-6) + pseudo-velocity


@dataclass
class SpherePolishingOptions:
    speed: float = 0.05                                          # m/s along the path
    start_angle: float = 0.0                                     # the path's angle s at the start
    chart: str = choice("pose", ("pose", "euler"))               # PoseChart or the paper's z-x-z angles
    path: str = choice("latitude", ("latitude", "pole"))
    velocity_rows: str = choice("true", ("true", "paper"))       # true-velocity rows or (3.3-11) + pseudo-velocity

    def __post_init__(self):
        # The paper's (3.3-11) rows are written in its z-x-z angles (core.projections.sphere_paper_projection):
        # refused here, when the options are read, not as a TypeError once the scenario is being built.
        if self.velocity_rows == "paper" and self.chart != "euler":
            raise ConfigError(f"task option velocity_rows=paper (the paper's (3.3-11) rows, in z-x-z Euler angles) "
                              f"needs chart=euler, got chart={self.chart}; with chart={self.chart} use "
                              "velocity_rows=true")


@dataclass
class GrindingOptions(WindowWashingOptions, SpherePolishingOptions):
    workpiece: str = choice("window", ("window", "sphere"))
    rough_friction: float = 0.9           # mu of the pad on the rough patch (window)
    rough_start: float = 1.05             # m, the patch along x
    rough_end: float = 1.15


@dataclass
class SurfacePolishingOptions:
    workpiece: str = choice("sphere", ("sphere", "bump", "saddle"))    # a sphere cap or a height-map part


SPHERE_ONLY = tuple(f.name for f in fields(SpherePolishingOptions))   # the sphere's path: no meaning on the window

# The built-in tasks' options, by task name, and the note each option's help line carries.
BUILT_IN_OPTIONS = {"window-washing": WindowWashingOptions, "crank-turning": CrankTurningOptions,
                    "sphere-polishing": SpherePolishingOptions, "grinding": GrindingOptions,
                    "surface-polishing": SurfacePolishingOptions}
OPTION_NOTES = {"grinding": {name: "workpiece=sphere only" for name in SPHERE_ONLY}}


def option_help(options, notes=None):
    """One line per field of the ``options`` dataclass for help texts: ``name=VALUE`` with its type or
    allowed values and default, then its note in ``notes`` (name -> text) if it has one."""
    lines = []
    for f in fields(options):
        allowed = f.metadata.get("allowed")
        kind = f.type if isinstance(f.type, type) else type(f.default)
        if allowed:
            value = "|".join(allowed)
        else:
            value = {bool: "true|false", int: "INTEGER", float: "NUMBER"}.get(kind, "WORD")
        note = (notes or {}).get(f.name)
        lines.append(f"{f.name}={value} (default {f.default})" + (f" ({note})" if note else ""))
    return lines


def built_in_option_help(name):
    """``option_help`` of the built-in task ``name``."""
    return option_help(BUILT_IN_OPTIONS[name], OPTION_NOTES.get(name))
