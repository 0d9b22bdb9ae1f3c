"""The paper's tasks as scenario recipes (robot, workpiece, constraint, start).

``get_task(name)`` returns a task object; ``TASKS`` lists them; ``register_task``
adds your own (``drake_hybrid.tasks.custom.CustomTask``). A task knows
how to add its robot and workpiece to a plant, its chart, constraint and
velocity projection, its default ScenarioConfig and its start configuration.
"""

from typing import Dict, Type, TypeVar

from drake_hybrid.core.arguments import describe, text
from drake_hybrid.core.errors import ArgumentError, DrakeHybridError
from drake_hybrid.tasks.builtin.crank_turning import CrankTurning
from drake_hybrid.tasks.builtin.grinding import Grinding
from drake_hybrid.tasks.builtin.sphere_polishing import SpherePolishing
from drake_hybrid.tasks.builtin.surface_polishing import SurfacePolishing
from drake_hybrid.tasks.builtin.window_washing import WindowWashing
from drake_hybrid.tasks.task import Task

TASKS: Dict[str, Task] = {task.name: task for task in (WindowWashing(), CrankTurning(), SpherePolishing(), Grinding(),
                                      SurfacePolishing())}


BUILT_IN_TASKS = frozenset(TASKS)
_Task = TypeVar("_Task", bound=Task)


def register_task(task: _Task) -> _Task:
    """Make ``task`` (e.g. a ``tasks.custom.CustomTask``) known by its name to ``get_task``, and so to
    ``build_scenario``, ``simulate`` and ``linearize_continuous``. A task registered earlier under
    the same name is replaced (re-running a notebook cell); a built-in task cannot be. Returns it."""
    if not isinstance(getattr(task, "name", None), str):
        raise ArgumentError(f"register_task: task must be a task object with a name (e.g. tasks.custom.CustomTask), "
                            f"got {describe(task)}")
    if task.name in BUILT_IN_TASKS:
        raise ArgumentError(f"'{task.name}' is a built-in task; give your task another name")
    TASKS[task.name] = task
    return task


def get_task(name: str, *, where: str = "get_task", error: Type[DrakeHybridError] = ArgumentError) -> Task:
    """The task registered as ``name`` (``TASKS``); ``error`` (one line, prefixed by ``where``: a config's
    ``task`` field gives its own) naming the known tasks for another name. ``where``: a string (the
    caller's name, or the config field's); ``error``: a DrakeHybridError subclass (ArgumentError,
    ConfigError, ...)."""
    text(where, "where", "get_task")
    if not (isinstance(error, type) and issubclass(error, DrakeHybridError)):
        raise ArgumentError(f"get_task: error must be a DrakeHybridError subclass (ArgumentError, ConfigError, ...), "
                            f"got {error.__name__ if isinstance(error, type) else describe(error)}")
    text(name, "name", where, error=error)
    try:
        return TASKS[name]
    except KeyError:
        raise error(f"{where}: unknown task '{name}'; available tasks: {', '.join(sorted(TASKS))} "
                    "(register_task adds your own)") from None
