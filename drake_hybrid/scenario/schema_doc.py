"""The task-file schema as a Markdown table, generated from the types (not written twice).

Every field of the task file (``scenario.data_task.TaskFile``) and of the ``ScenarioConfig`` it
embeds, by dotted name, with its type, its default and the comment written next to it in the
source (where units are given). ``docs/task_files.md`` is this module's output::

    python -m drake_hybrid.scenario.schema_doc > docs/task_files.md

(``tests/test_task_files.py`` checks that the file is up to date.)
"""

import dataclasses
import inspect
import re
import typing

from drake_hybrid.scenario.data_task import TaskFile
from drake_hybrid.scenario.hooks import ENTRY_POINT_GROUP, HOOK_METHODS, PACKAGE_HOOKS

_FIELD_LINE = re.compile(r"^\s+(\w+)\s*:\s*[^#]*?(?:#\s*(.*))?$")
# Drake's own types: documented by Drake, shown by name (and not expanded).
_DRAKE_LINKS = {
    "ModelDirective": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1parsing_1_1_model_directive.html",
    "Transform": "https://drake.mit.edu/doxygen_cxx/classdrake_1_1schema_1_1_transform.html",
    "MultibodyPlantConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1multibody_1_1_multibody_plant_config.html",
    "SimulatorConfig": "https://drake.mit.edu/doxygen_cxx/structdrake_1_1systems_1_1_simulator_config.html",
}


def field_comments(cls):
    """{field name: the comment on its line in the class's source} of a dataclass."""
    comments = {}
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return comments
    for line in source.splitlines():
        match = _FIELD_LINE.match(line)
        if match and match.group(2):
            comments.setdefault(match.group(1), match.group(2).strip())
    return comments


def type_name(kind):
    """A short readable name of a field type (List[float], Dict[str, float], A | B)."""
    origin, arguments = typing.get_origin(kind), typing.get_args(kind)
    if origin is typing.Union:
        return " | ".join(type_name(argument) for argument in arguments)
    if origin in (list, typing.List):
        return f"List[{type_name(arguments[0])}]"
    if origin in (dict, typing.Dict):
        return f"Dict[{', '.join(type_name(argument) for argument in arguments)}]"
    return getattr(kind, "__name__", str(kind))


def _summary(kind):
    """The first line of a class's own docstring ('' for a dataclass without one)."""
    text = (kind.__doc__ or "").strip()
    return "" if text.startswith(f"{kind.__name__}(") else text.split("\n")[0]


def _default_text(value):
    if dataclasses.is_dataclass(value) or hasattr(type(value), "__fields__"):
        return ""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list) and value and not isinstance(value[0], (int, float, str)):
        return ""
    return str(value)


def schema_rows(schema, prefix=""):
    """(dotted name, type, default, comment) of every field of ``schema``, nested sections expanded
    (Drake's own types are named, not expanded)."""
    rows = []
    instance = schema()
    comments = field_comments(schema)
    for item in dataclasses.fields(schema):
        kind = typing.get_type_hints(schema)[item.name]
        name = f"{prefix}{item.name}"
        default = getattr(instance, item.name)
        if dataclasses.is_dataclass(kind):
            rows.append((name, "section", "", comments.get(item.name, _summary(kind))))
            rows += schema_rows(kind, f"{name}.")
            continue
        element = typing.get_args(kind)[0] if typing.get_origin(kind) in (list, typing.List) else None
        if element is not None and dataclasses.is_dataclass(element):
            rows.append((f"{name}[]", f"List[{element.__name__}]", "[]", comments.get(item.name, "")))
            rows += schema_rows(element, f"{name}[].")
            continue
        rows.append((name, type_name(kind), _default_text(default), comments.get(item.name, "")))
    return rows


HOOKS_TEXT = [
    "## Hooks",
    "",
    "`hooks: [name, ...]` names Python hooks from a registry (`drake_hybrid/scenario/hooks.py`): the",
    "package's (below) and those installed packages declare in the entry point group",
    f"`{ENTRY_POINT_GROUP}` (each entry point a `TaskHook`), e.g. in their `pyproject.toml`:",
    "",
    "```toml",
    f'[project.entry-points."{ENTRY_POINT_GROUP}"]',
    'my_fixture = "my_package.hooks:MY_FIXTURE"       # a TaskHook named my_fixture',
    "```",
    "",
    "A name is a lower-case word; a `module:function` string, a dotted path or a file name is refused",
    "before any lookup, so a file can run only code that is installed and registered under a name. A",
    "hook reads the file's `parameters` it lists (all required) and supplies Task methods",
    f"({', '.join(HOOK_METHODS)}): `add_robot` instead of the `robot` section's models, `add_workpiece`",
    "after the file's workpiece, `constraint` instead of `constraint.rows`; two hooks of a file may not",
    "supply the same method. `drake-hybrid tasks` lists the known hooks. The package's:",
]

BUILT_IN_FILES_TEXT = [
    "## The built-in tasks as files",
    "",
    "Each runs as the built-in Python task: the same logs to 1e-9 and the same linearized eigenvalues",
    "(`tests/test_task_files.py`, `tests/test_task_hooks.py`). What is data and what is a hook, and why:",
    "",
    "- `window_washing.yaml`: all data.",
    "- `crank_turning.yaml` (default: true-velocity rows): the constraint (2.2-5), its branch and the",
    "  true-velocity rows are expressions, the crank a model directive welded at a pose given by the",
    "  parameters. Hooks: `ur5e_with_pad` (below) and `crank`: Drake's model directives have no",
    "  constraint directive, so the SAP weld constraint that holds the pad on the handle is Python; the",
    "  start is inverse kinematics to the handle's pose (no search for a pressing depth: the weld holds",
    "  the pad), the crank's joint state at the start, its inertia along the velocity rows",
    "  (`mechanism.source: plant`), the handle-inertia eigenvalue shifts and the run note compute with",
    "  the plant. The paper's (3.3-6) rows (`--option velocity_rows=paper`): the same file with the",
    "  rows `-(y - crank_center_y), x - crank_center_x, 0, 1, 0, 0` and the hook `crank_paper_rows`,",
    "  whose source turns the true-velocity command into the paper's pseudo-velocity (3.3-8).",
    "- `sphere_polishing.yaml` (default: latitude path, pose chart, true-velocity rows): the rows are",
    "  expressions of the pose chart's coordinates. Hooks: `sphere_paper_constraint`: the equator fix",
    "  of (2.2-8) drops, at each evaluation, the component of P x a with the largest |a_k|: three sets",
    "  of rows switched at run time, which one list of rows cannot say; `ur5e_with_pad`: the UR5e comes",
    "  from airo-models, which ships no package.xml (no `package://` URL reaches it), and the built-in",
    "  task drops its links' collision geometries. The start is a pose (six numbers) on the path. The",
    "  other variants (`path: pole`, `chart: euler`, `velocity_rows: paper`) are not written as files:",
    "  the first two are the same file with other rows and start; the paper's (3.3-11) rows need a",
    "  pseudo-velocity source hook for the sphere, which the package does not have.",
    "- `grinding.yaml` (default: the window with a rough patch, impedance/force): hook `rough_patch`:",
    "  the patch's own friction coefficient follows from `config.contact.friction` (Drake combines",
    "  2 mu1 mu2 / (mu1 + mu2); the pad must see `rough_friction` on it), and the run notes say where",
    "  the pad ends relative to the patch. The sphere variant (`workpiece: sphere`) is",
    "  `sphere_polishing.yaml` with the grinding gains, mode and friction; not written as a file.",
    "",
    "Task files have no task options (`--option`): a variant is another file.",
    "",
    "## URLs and expressions in poses",
    "",
    "`robot.loader.path` and the directives' `add_model.file` take `package://<name>/...` URLs: the",
    "package `drake_hybrid` (models/), the model packages pip installed in the cmeel layout",
    "(`<site-packages>/cmeel.prefix/share/<name>/package.xml`, e.g. `example-robot-data`) and the file's",
    "`packages: {name: folder}` (folders relative to the file); also `file://` URLs and paths (relative",
    "to the file). The number lists of poses outside `config` (`translation: [...]`, `rotation: !Rpy",
    "{deg: [...]}`: the directives' `X_PC`/`X_PF`, the shapes' `X_WG`, the tool's and the loader's poses)",
    "take expressions of the parameters, e.g. `X_PC: {translation: [crank_center_x, crank_center_y,",
    "crank_height]}`. A file shipped to Dask workers travels by its text: the files it names must be at",
    "the same paths (or in the same packages) there.",
]


def schema_markdown(schema=TaskFile):
    """The Markdown page of ``docs/task_files.md``."""
    lines = ["# Task files: every field",
             "",
             "Generated from the types by `python -m drake_hybrid.scenario.schema_doc` (do not edit by hand).",
             "A task file is described in `drake_hybrid/scenario/data_task.py`; examples are in `models/tasks/`.",
             "Expressions (constraint rows, E_p rows, the start) follow the grammar of",
             "`drake_hybrid/core/expressions.py`. Drake's own types are documented by Drake:",
             ""]
    lines += [f"- `{name}`: {url}" for name, url in _DRAKE_LINKS.items()]
    lines += ["", "| field | type | default | meaning |", "|---|---|---|---|"]
    for name, kind, default, comment in schema_rows(schema):
        cell = comment.replace("|", "\\|")
        lines.append(f"| `{name}` | {kind.replace('|', 'or')} | {default.replace('|', 'or')} | {cell} |")
    lines += ["", *HOOKS_TEXT, "", "| hook | provides | parameters it reads | plant | what |", "|---|---|---|---|---|"]
    for hook in PACKAGE_HOOKS:
        lines.append(f"| `{hook.name}` | {', '.join(hook.provides)} | {', '.join(hook.parameters) or '-'} | "
                     f"{'any' if hook.continuous_plant else 'discrete'} | {hook.description} |")
    lines += ["", *BUILT_IN_FILES_TEXT]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(schema_markdown(), end="")
