"""The paper's tasks as scenario recipes (robot, workpiece, constraint, start).

``get_task(name)`` returns a task object; ``TASKS`` lists them. A task knows
how to add its robot and workpiece to a plant, its chart, constraint and
velocity projection, its default ScenarioConfig and its start configuration.
"""

from drake_hybrid.tasks.crank_turning import CrankTurning
from drake_hybrid.tasks.sphere_polishing import SpherePolishing
from drake_hybrid.tasks.window_washing import WindowWashing

TASKS = {task.name: task for task in (WindowWashing(), CrankTurning(), SpherePolishing())}


def get_task(name):
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task '{name}'; available tasks: {sorted(TASKS)}") from None
